#!/usr/bin/env bash
# The main job on the embedded default (the SYNTHETIC demo dataset; no download needed):
# demo data -> simulated CenterPoint-like detections -> train the GRU-KF -> track demo_val with the EKF and
# the GRU-KF -> official nuScenes submission files -> official TrackingEval -> metrics JSON and a summary.
# Creates .venv if it is missing. Outputs: data/demo/, detections/, checkpoints/, submissions/, reports/metrics/.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/env.sh"
cd "$ROOT"
D=data/demo
V=v1.0-demo
SCENES="${GRUTRACK_DEMO_SCENES:-10}"
[ -f "$D/$V/scene.json" ] || grutrack demo-data --out "$D" --scenes "$SCENES" --seed 0
for split in demo_train demo_val; do
  seed=1; [ "$split" = demo_val ] && seed=2
  out="detections/demo_${split#demo_}_centerpoint_sim_s$seed.json"
  [ -f "$out" ] || grutrack simulate-detections --dataroot "$D" --version "$V" --split "$split" \
      --profile centerpoint --seed "$seed" --out "$out"
done
[ -f checkpoints/demo_grukf/model.pt ] || grutrack train --dataroot "$D" --version "$V" --split demo_train \
    --detections detections/demo_train_centerpoint_sim_s1.json --out checkpoints/demo_grukf --no-progress
for tracker in ekf grukf; do
  grutrack track --dataroot "$D" --version "$V" --split demo_val --tracker "$tracker" \
      --checkpoint checkpoints/demo_grukf/model.pt \
      --detections detections/demo_val_centerpoint_sim_s2.json --out "submissions/demo_val_$tracker.json" --no-progress
  grutrack evaluate --dataroot "$D" --version "$V" --split demo_val --submission "submissions/demo_val_$tracker.json" \
      --out "reports/metrics/demo_val_$tracker.json"
done
echo "demo (synthetic data): metrics in reports/metrics/demo_val_ekf.json and reports/metrics/demo_val_grukf.json"
