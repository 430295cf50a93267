#!/usr/bin/env bash
# Judges a candidate segmentation network where it matters, on the real clips, against the
# committed network and against a null swap (models/README.md, "Again, with the stronger teacher"):
#   cand  CHECKPOINT exported at 192x640, quantised (64 CamVid train images) and converted by
#         make_artefacts.sh;
#   null  the committed network rebuilt from its ONNX (onnx_to_checkpoint.py) and put through the
#         same steps, but calibrated on 65 images instead of 64: the same float weights, a slightly
#         different int8 network (with 64 the blob is byte for byte the committed one, and the
#         null comparison would be 1.000 by construction). How far it moves the clips' ATE is
#         the floor a candidate has to clear;
#   ref   the committed models/artefacts/fastscnn_r2_192x640.slm.
# Each runs `semloc ablate --semantics full,motion --assoc em --align sim3` from 13 starts of the
# KITTI 01 and 06 clips (frames 0-24:2) and 9 of drive 0005 (0-40:5). Then `semloc compare`
# prints, per clip, null / ref and cand / ref paired per start, then ref, null and cand against the
# backbone (off/hard, run once into OUTDIR/base-*) from the same starts (the JSONs beside them:
# compare-*.json and cmpbase-*.json).
# The backbone, ref and null runs are kept in OUTDIR and reused, so several candidates can be judged one
# after another into one OUTDIR; each candidate's runs and comparisons replace the previous one's.
# Calibration draws: on these clips the int8 calibration alone moves a network's figures as much as
# its training draw does (models/README.md, "Calibration draws"), so by default both the committed
# float weights and the candidate are also calibrated on 65, 66 and 67 images (DRAWS, default
# "65 66 67"; DRAWS="" judges the one draw only) and run (refK, candK; the committed weights' 65 are
# the null's runs), and draws_compare.py pairs the candidate with the committed network start by
# start over all their draws (64 and DRAWS), each also against the backbone with every draw's
# figure and their spread (OUTDIR/draws-*.json).
# Usage: bash models/judge_on_clips.sh CHECKPOINT VARIANT OUTDIR [SEMLOC_BINARY]
# VARIANT is read as export.py reads it: a checkpoint of train.py records its own, which wins.
# Env: SEMLOC_DATA (default ../shared/data beside the checkout). Needs a release build of semloc
# (default target/release/semloc) and models/'s Python. About 3 minutes per network and draw on
# 2 cores: about 12 minutes per candidate with the default draws (about 30 minutes the first time,
# with the backbone, ref, null and the committed weights' other draws).
set -euo pipefail
ckpt=$1; variant=$2; out=$3
here=$(cd "$(dirname "$0")" && pwd)
semloc=${4:-$here/../target/release/semloc}
data=${SEMLOC_DATA:-$here/../../shared/data}
committed=$here/artefacts/fastscnn_r2_192x640
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
for f in "$ckpt" "$semloc" "$committed.slm" "$committed.onnx"; do
  [ -f "$f" ] || { echo "judge_on_clips: $f: no such file" >&2; exit 1; }
done
for d in "$data/kitti-odometry/sequences/01" "$data/kitti-odometry/sequences/06" "$data/kitti-raw"; do
  [ -d "$d" ] || { echo "judge_on_clips: $d: no such folder (set SEMLOC_DATA)" >&2; exit 1; }
done
mkdir -p "$out"

# slm NAME CKPT VARIANT [CALIB]: make_artefacts.sh at 192x640 (CALIB calibration images, default 64)
# into $out/NAME/; the blob is
# $out/NAME/fastscnn_{r2,bn}_192x640.slm.
slm() {
  CALIB=${4:-64} SIZES=192x640 ARTEFACTS=$out/$1 bash "$here/make_artefacts.sh" "$2" "$3" "$semloc" \
    > "$out/$1.convert.log" 2>&1 || { echo "judge_on_clips: $1: conversion failed, see $out/$1.convert.log" >&2; exit 1; }
}
# blob NAME: the path of slm NAME's blob.
blob() { ls "$out/$1"/fastscnn_*_192x640.slm; }

# ablate NAME SLM: the three clips' runs in $out/NAME-{01,06,0005}, skipped where they exist.
# SLM "-" runs the backbone (off/hard) instead, with no network.
ablate() {
  local rows=(--semantics full,motion --assoc em --model "$2" --align sim3 --force) c src starts
  [ "$2" = - ] && rows=(--semantics off --assoc hard --align sim3 --force)
  for c in 01 06 0005; do
    [ -f "$out/$1-$c/ablation.json" ] && continue
    case $c in
      0005) src=("$data/kitti-raw" --drive 2011_09_26_0005); starts=0-40:5 ;;
      *) src=("$data/kitti-odometry" --seq "$c"); starts=0-24:2 ;;
    esac
    "$semloc" ablate "${src[@]}" "${rows[@]}" --first-frames "$starts" --out "$out/$1-$c" \
      > "$out/$1-$c.log" 2>&1 || { echo "judge_on_clips: $1 on $c failed, see $out/$1-$c.log" >&2; exit 1; }
  done
}

if ! blob null > /dev/null 2>&1; then
  python3 "$here/onnx_to_checkpoint.py" "$committed.onnx" --variant res2net --out "$out/null.pt" \
    > "$out/null.rebuild.log" 2>&1 || { echo "judge_on_clips: rebuilding the committed network failed, see $out/null.rebuild.log" >&2; exit 1; }
  slm null "$out/null.pt" res2net 65
fi
draws=(${DRAWS-65 66 67})
seen=" 64 "
for k in "${draws[@]}"; do
  [[ $k =~ ^[1-9][0-9]*$ && $seen != *" $k "* ]] || {
    echo "judge_on_clips: DRAWS: '$k' is not a number of calibration images other than 64 and the other draws" >&2; exit 1; }
  seen+="$k "
done
rm -rf "$out"/cand "$out"/cand[0-9]* "$out"/cand-01 "$out"/cand-06 "$out"/cand-0005
slm cand "$ckpt" "$variant"
ablate base -
ablate ref "$committed.slm"
ablate null "$(blob null)"
ablate cand "$(blob cand)"
# draw_runs SIDE K: the name of SIDE's runs calibrated on K images (ref's 65 are the null's).
draw_runs() {
  if [ "$1" = ref ] && [ "$2" = 65 ]; then echo null; else echo "$1$2"; fi
}
for k in "${draws[@]}"; do
  if [ "$(draw_runs ref "$k")" != null ]; then
    blob "ref$k" > /dev/null 2>&1 || slm "ref$k" "$out/null.pt" res2net "$k"
    ablate "ref$k" "$(blob "ref$k")"
  fi
  slm "cand$k" "$ckpt" "$variant" "$k"
  ablate "cand$k" "$(blob "cand$k")"
done
for c in 01 06 0005; do
  for v in null cand; do
    echo "== $c: $v / ref"
    "$semloc" compare "$out/ref-$c" "$out/$v-$c" --json "$out/compare-$v-$c.json" | grep -E "/em"
  done
done
# The issue's target is against the backbone: never more than 3 % worse on a real clip.
for c in 01 06 0005; do
  for v in ref null cand; do
    echo "== $c: $v / backbone (off/hard)"
    "$semloc" compare "$out/base-$c" "$out/$v-$c" --against off/hard --json "$out/cmpbase-$v-$c.json" | grep -E "/em"
  done
done
if [ ${#draws[@]} -gt 0 ]; then
  # Over the calibration draws: the candidate against the committed network, and each against the backbone.
  for c in 01 06 0005; do
    refs=("$out/ref-$c") cands=("$out/cand-$c")
    for k in "${draws[@]}"; do refs+=("$out/$(draw_runs ref "$k")-$c"); cands+=("$out/cand$k-$c"); done
    echo "== $c: over calibration draws 64 ${draws[*]}"
    python3 "$here/draws_compare.py" --ref "${refs[@]}" --cand "${cands[@]}" --base "$out/base-$c" \
      --json "$out/draws-$c.json" | tail -n +2
  done
fi
