#!/usr/bin/env bash
# Re-train the shipped pretrained GRU-KF (grutrack/pretrained/grukf_default/) through the workflow: the training
# `grukf_default` of workflow/config/mini.yaml (the default recipe, grutrack/configs/training/grukf.yaml, on
# nuScenes mini_train with simulated CenterPoint-like detections, seed 1, plus the recipe's SYNTHETIC 700-scene
# source), packaged by rule package_pretrained and copied into the package. Run it when the default recipe or the
# default tracker (preset or motion config) changes: tests/test_grukf_real.py fails, naming what changed, until the
# checkpoint matches the shipped recipe and tracker again (provenance.json's trained_with).
# Its time: docs/results/pretrained.md. Data: ../shared/data/nuscenes (as workflow/config/mini.yaml says).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/env.sh"
cd "$ROOT"
snakemake --cores "${GRUTRACK_CORES:-2}" pretrained/grukf_default/provenance.json \
    --configfile workflow/config/mini.yaml "$@"
for f in model.pt training.yaml train_log.csv validation.json provenance.json; do
    cp "pretrained/grukf_default/$f" "grutrack/pretrained/grukf_default/$f.tmp"
    mv "grutrack/pretrained/grukf_default/$f.tmp" "grutrack/pretrained/grukf_default/$f"
done
echo "grutrack/pretrained/grukf_default/ updated: $(grep -o '"model_sha256": "[0-9a-f]*' grutrack/pretrained/grukf_default/provenance.json)"
