#!/usr/bin/env bash
# Regenerate the example bags in bags/ (run from the repository root; needs the .venv from `make setup`).
set -euo pipefail
cd "$(dirname "$0")/.."
CONVERT="${CONVERT:-.venv/bin/riann-bag-convert}"
$CONVERT --format synthetic --motion combined    --rate 200 --duration 60 --seed 1 --compression zstd --force -o bags/synthetic_combined_200hz.mcap
$CONVERT --format synthetic --motion rotation    --rate 100 --duration 60 --seed 2 --compression zstd --force -o bags/synthetic_rotation_100hz.mcap
$CONVERT --format synthetic --motion translation --rate 200 --duration 60 --seed 3 --compression zstd --force -o bags/synthetic_translation_200hz.mcap
# The demo's real recording: one BROAD trial (CC BY 4.0; attribution in bags/README.md and in the bag's /dataset/info).
# Needs the BROAD files: $RIANN_BROAD_DIR, else ../shared/datasets/broad.
BROAD="${RIANN_BROAD_DIR:-../shared/datasets/broad}"
$CONVERT "$BROAD/21_undisturbed_fast_combined.mat" --compression zstd --force -o bags/broad_21_undisturbed_fast_combined.mcap
