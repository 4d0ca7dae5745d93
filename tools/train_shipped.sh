#!/usr/bin/env bash
# The commands that trained the shipped checkpoints (icrsumo/learn/checkpoints/NAME.pt from
# NAME.toml), all three at once on one GPU. Usage, from the repository root:
#
#   bash tools/train_shipped.sh OUT DATA [DATA ...]
#
# DATA: folders written by `icrsumo collect` (see each model card for the ones used).
# Works without icrsumo installed (PYTHONPATH is the checkout), e.g. on the device machine.
set -euo pipefail
out=$1; shift
data=()
for d in "$@"; do data+=(--data "$d"); done
mkdir -p "$out"
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
for n in ${MODELS:-bev-token bev-ngram bev-ngram-aug}; do
  python3 -m icrsumo train "icrsumo/learn/checkpoints/$n.toml" "${data[@]}" --out "$out/$n" \
    > "$out/$n.log" 2>&1 &
done
wait
for n in ${MODELS:-bev-token bev-ngram bev-ngram-aug}; do tail -n 2 "$out/$n.log"; done
