#!/usr/bin/env bash
# Re-train the shipped pretrained GRU-KF (grutrack/pretrained/grukf_default/): the default recipe as shipped
# (grutrack/configs/training/grukf.yaml: nuScenes mini_train plus the recipe's 700-scene SYNTHETIC demo source,
# 3 epochs, detections resampled over three profiles, 2 mini_train scenes held out for validation) on mini_train
# with simulated CenterPoint-like detections (seed 1). Run it when the default recipe changes:
# tests/test_grukf_real.py fails until the checkpoint matches the shipped recipe again. Its time on one core:
# docs/results/pretrained.md. Data: ../shared/data/nuscenes (override with GRUTRACK_TEST_DATA).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/env.sh"
DATA="${GRUTRACK_TEST_DATA:-$ROOT/../shared/data}/nuscenes"
OUT="$ROOT/grutrack/pretrained/grukf_default"
WORK="$(mktemp -d "${TMPDIR:-/tmp}/grutrack-pretrain-XXXXXX")"
trap 'rm -rf "$WORK"' EXIT
grutrack simulate-detections --dataroot "$DATA" --version v1.0-mini --split mini_train --profile centerpoint \
    --seed 1 --out "$WORK/mini_train_centerpoint_s1.json"
grutrack train --dataroot "$DATA" --version v1.0-mini --split mini_train \
    --detections "$WORK/mini_train_centerpoint_s1.json" --out "$WORK/ck" --no-progress
python -m grutrack.training.pretrained --from "$WORK/ck" --detections "$WORK/mini_train_centerpoint_s1.json" \
    --out "$OUT" --command "bash scripts/pretrain_grukf.sh"
