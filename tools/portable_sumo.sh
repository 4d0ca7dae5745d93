#!/usr/bin/env bash
# Run `icrsumo evaluate` on a machine that has Python and torch but no SUMO and no network
# (the lent GPU machine's CPU cores): pack libsumo there in parts that each fit one transfer,
# then unpack and run. This is how LangAuto-long's learned-agent table in the README was run.
#
# Here (with network, the project's venv active), from the repository root:
#   bash tools/portable_sumo.sh pack DIR [PYVER]      # PYVER of the target, default 3.12
# writes DIR/part-1 (libsumo, first 40 MB), DIR/part-2 (the rest, the pure-Python wheels and
# the X/GL client libraries libsumo links against) and DIR/part-3 (ONNX Runtime and onnx, the
# learned agents' CPU inference), each under 64 MiB with the checkout.
# Converted scenarios and instructions travel in a third call: copy
# OUT/{scenarios,instructions,config.json} of a local `icrsumo evaluate` run (converting needs
# SUMO's tools, which are not packed) and run evaluate on that copy.
#
# There (each part in its own call while the machine stays warm; /tmp persists):
#   bash tools/portable_sumo.sh stage DIR/part-1      # keeps it in /tmp/portable_sumo
#   bash tools/portable_sumo.sh install DIR/part-2    # unpacks into /tmp/site
#   bash tools/portable_sumo.sh wheels DIR/part-3     # installs its wheels into /tmp/site
#   source <(bash tools/portable_sumo.sh env)         # PYTHONPATH and LD_LIBRARY_PATH
#   python3 -m icrsumo evaluate ... --out COPIED_OUT --workers 16
#
# Scores of the learned agents differ slightly between CPUs and torch builds (README, "Same
# command, another CPU"); the privileged agents use no torch.
set -euo pipefail
stage=/tmp/portable_sumo
cmd=${1:?pack | stage | install | wheels | env}
case "$cmd" in
  pack)
    dir=$(realpath -m "${2:?DIR}"); py=${3:-3.12}; tag=${py/./}
    # this venv's python by an absolute path (the steps below change folder; PATH may be relative)
    py3=$(command -v python3); py3="$(cd "$(dirname "$py3")" && pwd)/$(basename "$py3")"
    python3() { "$py3" "$@"; }
    mkdir -p "$dir/part-1" "$dir/part-2" "$dir/part-3" "$dir/wheels"
    opts=(--no-deps --only-binary=:all: --python-version "$py" --implementation cp
          --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64
          --platform manylinux2014_x86_64 -d "$dir/wheels")
    v=$(python3 -c "import importlib.metadata as m; print(m.version('libsumo'))")
    python3 -m pip download -q "${opts[@]}" "libsumo==$v" "sumolib==$v" "traci==$v" \
      "sumo-data==$v" shapely defusedxml gymnasium farama-notifications
    tmp=$(mktemp -d)
    (cd "$tmp" && python3 -m zipfile -e "$dir/wheels/libsumo-$v-cp$tag-"*.whl .)
    tar cf - -C "$tmp" libsumo libsumo.libs | xz -6 -T0 | split -b 40000000 - "$tmp/libsumo.tar.xz."
    mv "$tmp/libsumo.tar.xz.aa" "$dir/part-1/"
    mv "$tmp/libsumo.tar.xz."a[b-z] "$dir/part-2/"
    rm -rf "$tmp" "$dir/wheels/libsumo-"*.whl
    mv "$dir/wheels/"*.whl "$dir/part-2/"
    python3 -m pip download -q "${opts[@]}" onnxruntime onnx flatbuffers protobuf ml_dtypes
    mv "$dir/wheels/"*.whl "$dir/part-3/" && rmdir "$dir/wheels"
    mkdir -p "$dir/part-2/lib"
    python3 - "$dir/part-2/lib" <<'EOF'
import shutil, subprocess, sys
from pathlib import Path
import libsumo
so = next(Path(libsumo.__file__).parent.glob("_libsumo*.so"))
keep = ("libX", "libxcb", "libGL", "libbsd", "libmd.", "libexpat", "libatomic")
for line in subprocess.run(["ldd", str(so)], capture_output=True, text=True).stdout.splitlines():
    parts = line.split()
    if len(parts) >= 3 and parts[0].startswith(keep) and parts[2].startswith(("/lib", "/usr/lib")):
        shutil.copy(parts[2], Path(sys.argv[1]) / parts[0])
EOF
    du -sh "$dir/part-1" "$dir/part-2" "$dir/part-3" ;;
  stage)
    mkdir -p "$stage" && cp "${2:?DIR/part-1}"/libsumo.tar.xz.* "$stage/" ;;
  install)
    part=${2:?DIR/part-2}
    cp "$part"/libsumo.tar.xz.* "$stage/"
    mkdir -p /tmp/site /tmp/portable_lib
    cat "$stage"/libsumo.tar.xz.* | xz -d | tar xf - -C /tmp/site
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site \
      "$part"/*.whl
    for f in "$part"/lib/*; do  # only the client libraries the machine lacks
      ldconfig -p | grep -q "$(basename "$f") " || cp "$f" /tmp/portable_lib/
    done
    # icrsumo asks the eclipse-sumo wheel for SUMO's home; sumo-data's folder serves a run
    mkdir -p /tmp/site/sumo
    echo "import sumo_data; SUMO_HOME = sumo_data.__path__[0]" > /tmp/site/sumo/__init__.py
    PYTHONPATH=/tmp/site:$PWD LD_LIBRARY_PATH=/tmp/portable_lib python3 -c "import libsumo, icrsumo" ;;
  wheels)
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site \
      "${2:?DIR/part-3}"/*.whl
    PYTHONPATH=/tmp/site:$PWD python3 -c "import onnxruntime, onnx" ;;
  env)
    echo "export PYTHONPATH=/tmp/site:$PWD LD_LIBRARY_PATH=/tmp/portable_lib" ;;
  *) echo "portable_sumo.sh: unknown command $cmd (fix: pack, stage, install, wheels or env)" >&2; exit 2 ;;
esac
