// Screenshots of Rerun's web viewer in headless Chromium (Debian's chromium, driven by
// playwright-core). Called by fence_sorter/visualisation/browser.py with one JSON argument:
//
//   {"chromium": "/usr/bin/chromium", "width": 1280, "height": 800, "timeout_ms": 240000,
//    "settle_ms": 1500, "url": "http://127.0.0.1:W/?url=...", "files": ["recording.rrd"],
//    "shots": [{"name": "mid", "png": "/path/mid.png", "actions": [{"click": [x, y]}]}]}
//
// It opens the page once, waits until every file named in "files" has been fetched, then per
// shot does its actions (clicks, key presses) and waits until two screenshots settle_ms apart
// are identical (the viewer has drawn and stopped changing), bounded by timeout_ms, and writes
// the PNG. Requests to any host but this machine are refused and listed. It prints one JSON
// line per shot: {"name", "png", "settled", "console_errors", "page_errors",
// "external_requests"}; the caller judges them. The egui canvas has no DOM to query: the PNGs
// are the evidence.
import { chromium } from "playwright-core";
import { writeFileSync } from "node:fs";

const cfg = JSON.parse(process.argv[2]);
const browser = await chromium.launch({
  executablePath: cfg.chromium,
  headless: true,
  args: [
    "--no-sandbox", // as root there is no user-namespace sandbox
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--ignore-gpu-blocklist",
  ],
});

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
let failed = false;
try {
  const page = await browser.newPage({
    viewport: { width: cfg.width, height: cfg.height },
    deviceScaleFactor: 1,
  });
  let consoleErrors = [];
  let pageErrors = [];
  let external = [];
  page.on("console", (msg) => {
    if (msg.type() === "error") consoleErrors.push(msg.text());
  });
  page.on("pageerror", (err) => pageErrors.push(String(err)));
  await page.route(
    (url) => !["127.0.0.1", "localhost"].includes(url.hostname),
    (route) => {
      external.push(route.request().url());
      return route.abort("blockedbyclient");
    },
  );
  const pending = new Set(cfg.files ?? []);
  const arrived = new Promise((resolve) => {
    if (pending.size === 0) resolve();
    page.on("requestfinished", (req) => {
      pending.delete(new URL(req.url()).pathname.split("/").pop());
      if (pending.size === 0) resolve();
    });
  });
  await page.goto(cfg.url, { waitUntil: "load", timeout: cfg.timeout_ms });
  const loaded = await Promise.race([arrived.then(() => true), sleep(cfg.timeout_ms)]);
  if (!loaded) throw new Error(`not fetched within ${cfg.timeout_ms} ms: ${[...pending]}`);

  for (const shot of cfg.shots) {
    for (const a of shot.actions ?? []) {
      if (a.wait_ms) await sleep(a.wait_ms);
      if (a.click) await page.mouse.click(a.click[0], a.click[1]);
      if (a.key) await page.keyboard.press(a.key);
    }
    await page.mouse.move(300, 16); // the empty top bar: no hover tooltip in the picture
    const deadline = Date.now() + cfg.timeout_ms;
    let previous = null;
    let current = null;
    let settled = false;
    while (Date.now() < deadline) {
      await sleep(cfg.settle_ms);
      current = await page.screenshot({ type: "png", timeout: cfg.timeout_ms });
      if (previous !== null && current.equals(previous)) {
        settled = true;
        break;
      }
      previous = current;
    }
    writeFileSync(shot.png, current);
    console.log(
      JSON.stringify({
        name: shot.name,
        png: shot.png,
        settled,
        console_errors: consoleErrors,
        page_errors: pageErrors,
        external_requests: external,
      }),
    );
    consoleErrors = [];
    pageErrors = [];
    external = [];
  }
} catch (err) {
  console.error(`shoot.mjs: ${err}`);
  failed = true;
} finally {
  await browser.close();
}
process.exit(failed ? 1 : 0);
