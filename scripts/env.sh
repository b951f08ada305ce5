# shellcheck shell=bash
# Source me: `source scripts/env.sh`. Puts the fence_sorter venv on PATH and into the ament
# index. Nothing else is needed: fence_sorter_msgs is installed into the venv itself, so its
# libraries are in <venv>/lib, which the ros-wheels bootstrapper (a .pth file that re-executes
# python once with LD_LIBRARY_PATH extended by <venv>/lib and the wheels' *.libs directories)
# covers for every python started from the venv, and its Python package is in site-packages.
_fs_root="$(cd "$(dirname "${BASH_SOURCE[0]:-$0}")/.." && pwd)"
# FENCE_SORTER_ROS_DISTRO picks the venv as scripts/bootstrap.sh does: jazzy (default) .venv,
# kilted .venv-kilted; FENCE_SORTER_VENV overrides it.
case "${FENCE_SORTER_ROS_DISTRO:-jazzy}" in
  kilted) _fs_venv="${FENCE_SORTER_VENV:-$_fs_root/.venv-kilted}" ;;
  *) _fs_venv="${FENCE_SORTER_VENV:-$_fs_root/.venv}" ;;
esac

export VIRTUAL_ENV="$_fs_venv"
case ":$PATH:" in
  *":$_fs_venv/bin:"*) ;;
  *) export PATH="$_fs_venv/bin:$PATH" ;;
esac
# ros2 run / ament_index_python resolve packages from this list of prefixes.
case ":${AMENT_PREFIX_PATH:-}:" in
  *":$_fs_venv:"*) ;;
  *) export AMENT_PREFIX_PATH="$_fs_venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
esac
# A python of another venv may have bootstrapped this shell's parent already; let ours
# compute LD_LIBRARY_PATH for this venv again.
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE
# rcl writes its log files here (default ~/.ros/log; keep them in the work tree).
export ROS_LOG_DIR="${ROS_LOG_DIR:-$_fs_root/.build/ros_log}"
unset _fs_root _fs_venv
