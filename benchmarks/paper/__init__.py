"""The optimisation sweeps behind the paper's Figs. 3-10 and the controller's decision table
(``python -m benchmarks paper-sweep``): the points of each figure (:mod:`.sweep_defs`,
:mod:`.decision`, :mod:`.points`), one optimum per CSV row with resume (:mod:`.sweep_rows`),
the run, the nesting repair and the plots (:mod:`.sweep`)."""
