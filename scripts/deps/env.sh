# Environment for building and running hrc-adapt with the libraries scripts/setup put under
# .deps/. Source it from bash (or any POSIX shell) — it only exports variables:
#
#     source scripts/deps/env.sh
#
# - ORT_DYLIB_PATH: the ONNX Runtime library (.deps/onnxruntime/libonnxruntime.so), unless it is
#   already set;
# - when librealsense2 comes from the pyrealsense2 wheel (.deps/realsense/, no system
#   librealsense2): PKG_CONFIG_PATH gains .deps/realsense/lib/pkgconfig (for realsense-sys's
#   build script) and LD_LIBRARY_PATH gains .deps/realsense/lib (the library and the libpython
#   it needs, for running binaries and tests built with `--features realsense`).
# - UR_RTDE_INCLUDE, UR_RTDE_LIB_DIR (and LD_LIBRARY_PATH): ur_rtde 1.6.5's headers and library
#   for the `ur-rtde` feature, when scripts/deps/ur_rtde installed them.
#
# Sourcing it twice adds nothing twice.

# The repository root, from this file's location (bash: BASH_SOURCE; other shells: the
# working directory, which must then be the repository root).
if [ -n "${BASH_SOURCE:-}" ]; then
    hrc_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
else
    hrc_root=$(pwd)
fi

hrc_prepend() { # hrc_prepend VAR DIR: put DIR first in the colon-separated VAR, once.
    eval "hrc_current=\${$1:-}"
    case ":$hrc_current:" in
        *":$2:"*) ;;
        *) eval "export $1=\"$2\${hrc_current:+:\$hrc_current}\"" ;;
    esac
    unset hrc_current
}

if [ -z "${ORT_DYLIB_PATH:-}" ] && [ -e "$hrc_root/.deps/onnxruntime/libonnxruntime.so" ]; then
    export ORT_DYLIB_PATH="$hrc_root/.deps/onnxruntime/libonnxruntime.so"
fi

if [ -f "$hrc_root/.deps/realsense/lib/pkgconfig/realsense2.pc" ]; then
    hrc_prepend PKG_CONFIG_PATH "$hrc_root/.deps/realsense/lib/pkgconfig"
    hrc_prepend LD_LIBRARY_PATH "$hrc_root/.deps/realsense/lib"
fi

# ur_rtde 1.6.5 (the `ur-rtde` feature): the sdist's headers (.deps/ur_rtde/include) and the
# wheel's librtde.so (the venv's site-packages), for robot-io/build.rs and at run time.
hrc_rtde_lib="$hrc_root/.deps/ur_rtde-venv/lib/python3.11/site-packages"
if [ -f "$hrc_root/.deps/ur_rtde/include/ur_rtde/rtde_receive_interface.h" ] && [ -f "$hrc_rtde_lib/librtde.so.1.6.5" ]; then
    export UR_RTDE_INCLUDE="$hrc_root/.deps/ur_rtde/include"
    export UR_RTDE_LIB_DIR="$hrc_rtde_lib"
    hrc_prepend LD_LIBRARY_PATH "$hrc_rtde_lib"
fi
unset hrc_rtde_lib

unset -f hrc_prepend
unset hrc_root
