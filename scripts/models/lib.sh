# Shared by scripts/models/convert and scripts/models/reference (sourced, not run).
#
# The model toolchain lives in two Python venvs under the git-ignored .deps/model-tools/:
#   venv-convert  tensorflow-cpu 2.15.1 (its TFLite interpreter folds the weights), tf2onnx 1.16.1
#   venv-runtime  mediapipe 0.10.21 (with opencv-contrib-python), onnxruntime 1.31.1,
#                 tflite-runtime 2.14.0: the reference landmarks and the ONNX-vs-TFLite check
# They cannot be one venv: tf2onnx 1.16.1 needs protobuf 3.20; mediapipe 0.10.21 and
# onnxruntime 1.31.1 need protobuf 4.25. Python 3.11 is needed (tensorflow-cpu 2.15.1 has no
# wheel for 3.12+, onnxruntime 1.31.1 none below 3.11); set PYTHON to choose the interpreter,
# default python3.11. Each venv is installed from the fully pinned
# requirements-*.txt beside this file; requirements-*.in hold the top-level pins they came from.

models_dir=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
repo_root=$(cd "$models_dir/../.." && pwd)
tools_dir="$repo_root/.deps/model-tools"
downloads_dir="$tools_dir/downloads"
work_dir="$tools_dir/work"

log() { echo "models: $*" >&2; }

# ensure_venv NAME: create .deps/model-tools/venv-NAME from requirements-NAME.txt unless it is
# already there with the same requirements file.
ensure_venv() {
    local name=$1
    local venv="$tools_dir/venv-$name"
    local req="$models_dir/requirements-$name.txt"
    local stamp="$venv/.requirements-sha256"
    local want
    want=$(sha256sum "$req" | cut -d' ' -f1)
    if [ -x "$venv/bin/python" ] && [ "$(cat "$stamp" 2>/dev/null)" = "$want" ]; then
        return 0
    fi
    local py=${PYTHON:-python3.11}
    if ! command -v "$py" >/dev/null 2>&1; then
        log "need Python 3.11 (or 3.9/3.10) as '$py'; on Debian: apt-get install python3.11 python3.11-venv, or set PYTHON"
        return 1
    fi
    log "creating $venv with $($py --version 2>&1) from $(basename "$req") (about 1.2 GB each)"
    rm -rf "$venv"
    mkdir -p "$tools_dir"
    "$py" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --upgrade "pip==24.3.1"
    "$venv/bin/python" -m pip install --quiet --require-virtualenv -r "$req"
    echo "$want" >"$stamp"
}
