#!/usr/bin/env bash
# The commands that trained the shipped checkpoints (icrsumo/learn/checkpoints/NAME.pt from
# NAME.toml), all three at once, one GPU each where several are visible (else all on the one).
# Usage, from the repository root:
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
gpus=$(python3 -c "import torch; print(max(torch.cuda.device_count(), 1))" 2>/dev/null || echo 1)
i=0
for n in ${MODELS:-bev-token bev-ngram bev-ngram-aug}; do
  CUDA_VISIBLE_DEVICES=${CUDA_VISIBLE_DEVICES:-$((i % gpus))} \
    python3 -m icrsumo train "icrsumo/learn/checkpoints/$n.toml" "${data[@]}" --out "$out/$n" \
    > "$out/$n.log" 2>&1 &
  i=$((i + 1))
done
wait
for n in ${MODELS:-bev-token bev-ngram bev-ngram-aug}; do tail -n 2 "$out/$n.log"; done
