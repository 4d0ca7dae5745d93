#!/usr/bin/env bash
# Run the same evaluation on another machine's CPU (the lent GPU machine: Python, no SUMO, no
# network) with the same packages as here, and compare episode by episode (docs/exact.md).
#
# Here (the project's venv active, from the repository root; DIR inside the checkout and ignored,
# e.g. .devpack listed in .git/info/exclude, so that each call can carry one chunk; the float
# checkpoints icrsumo/learn/checkpoints/*.pt are not needed there: move them out of the tree
# during the calls, or tree and chunk exceed one transfer):
#   bash tools/cross_cpu.sh bundle DIR [PYVER]   # libsumo, its client libraries, and numpy,
#       # OpenCV, tokenizers and the pure-Python wheels at this venv's versions for PYVER (default
#       # 3.12), as DIR/cNN/chunk.NN of 24 MB (each fits one transfer with the checkout)
#   bash tools/cross_cpu.sh copy OUT DIR/runs/NAME   # OUT/{config.json,scenarios,instructions}
# There (one call per chunk while the machine stays warm; /tmp persists):
#   bash tools/cross_cpu.sh stage DIR/cNN          # each chunk into /tmp/stage
#   bash tools/cross_cpu.sh install                # unpack into /tmp/site
#   source <(bash tools/cross_cpu.sh env)
#   bash tools/cross_cpu.sh run DIR/runs/NAME RESULTS [evaluate options...]
# "run" evaluates a copy of the folder with 16 workers and writes RESULTS/NAME.hashes (one line
# per episode: key and the SHA-256 of its log) and RESULTS/NAME.summary.json, and prints the
# run's digest: the same digest as the run here means every episode is the same.
set -euo pipefail
cmd=${1:?bundle | copy | stage | install | env | run}
case "$cmd" in
  bundle)
    dir=$(realpath -m "${2:?DIR}"); py=${3:-3.12}
    tmp=$(mktemp -d)
    bash "$(dirname "$0")/portable_sumo.sh" pack "$tmp/pack" "$py" >/dev/null
    mkdir -p "$tmp/b/wheels" "$tmp/b/lib"
    cp "$tmp/pack/part-1/"libsumo.tar.xz.* "$tmp/pack/part-2/"libsumo.tar.xz.* "$tmp/b/"
    cp "$tmp/pack/part-2/"*.whl "$tmp/b/wheels/"
    cp "$tmp/pack/part-2/lib/"* "$tmp/b/lib/" 2>/dev/null || true
    pins=$(python3 -c "import importlib.metadata as m; print(' '.join(f'{n}=={m.version(n)}' for n in ('numpy', 'opencv-python-headless', 'tokenizers', 'threadpoolctl')))")
    # shellcheck disable=SC2086
    python3 -m pip download -q --no-deps --only-binary=:all: --python-version "$py" --implementation cp \
      --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
      --platform manylinux2014_x86_64 -d "$tmp/b/wheels" $pins
    tar cf "$tmp/b.tar" -C "$tmp/b" .
    mkdir -p "$dir"
    (cd "$dir" && split -b 24000000 -d "$tmp/b.tar" chunk. && for f in chunk.*; do mkdir -p "c${f#chunk.}" && mv "$f" "c${f#chunk.}/"; done)
    rm -rf "$tmp"; ls "$dir" ;;
  copy)
    src=${2:?OUT}; dst=${3:?DIR/runs/NAME}
    mkdir -p "$dst" && cp -r "$src/config.json" "$src/scenarios" "$src/instructions" "$dst/" ;;
  stage)
    mkdir -p /tmp/stage && cp "${2:?DIR/cNN}"/chunk.* /tmp/stage/ && ls /tmp/stage ;;
  install)
    rm -rf /tmp/b && mkdir -p /tmp/b /tmp/site /tmp/portable_lib
    cat /tmp/stage/chunk.* | tar xf - -C /tmp/b
    cat /tmp/b/libsumo.tar.xz.* | xz -d | tar xf - -C /tmp/site
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site /tmp/b/wheels/*.whl
    for f in /tmp/b/lib/*; do ldconfig -p | grep -q "$(basename "$f") " || cp "$f" /tmp/portable_lib/; done
    mkdir -p /tmp/site/sumo
    echo "import sumo_data; SUMO_HOME = sumo_data.__path__[0]" > /tmp/site/sumo/__init__.py
    PYTHONPATH=/tmp/site:$PWD LD_LIBRARY_PATH=/tmp/portable_lib python3 -c \
      "import libsumo, icrsumo, numpy, cv2, tokenizers; print('numpy', numpy.__version__, 'cv2', cv2.__version__, 'tokenizers', tokenizers.__version__)" ;;
  env)
    echo "export PYTHONPATH=/tmp/site:$PWD LD_LIBRARY_PATH=/tmp/portable_lib" ;;
  run)
    src=${2:?DIR/runs/NAME}; res=${3:?RESULTS}; shift 3
    name=$(basename "$src"); out=/tmp/runs/$name
    mkdir -p /tmp/runs "$res" && rm -rf "$out" && cp -r "$src" "$out"
    python3 -m icrsumo evaluate --out "$out" --workers "${WORKERS:-16}" --quiet "$@" >/dev/null
    cp "$out/summary.json" "$res/$name.summary.json"
    python3 - "$out/results.sqlite" "$res/$name.hashes" <<'EOF'
import json, sys
from icrsumo.evaluation.digests import store_hashes
from icrsumo.results.store import ResultStore
with ResultStore(sys.argv[1]) as s:
    lines = [json.dumps([*e.key, e.kind, e.sha256]) for e in store_hashes(s)]
open(sys.argv[2], "w").write("\n".join(lines) + "\n")
EOF
    python3 -m icrsumo digest "$out" ;;
  *) echo "cross_cpu.sh: unknown command $cmd (fix: bundle, copy, stage, install, env or run)" >&2; exit 2 ;;
esac
