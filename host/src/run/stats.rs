//! Statistics over a run's per-frame records: nearest-rank percentiles of the stage timings
//! and the medians of the per-frame counters that `summary.json` reports.
//!
//! Memory: one sorted copy of one column at a time (8 bytes per frame).

use std::collections::BTreeMap;

use super::FrameRecord;

/// Median, p90, p99 and max of one timing column.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Percentiles {
    /// Median (ms).
    pub median_ms: f64,
    /// 90th percentile (ms).
    pub p90_ms: f64,
    /// 99th percentile (ms).
    pub p99_ms: f64,
    /// Maximum (ms).
    pub max_ms: f64,
}

/// Nearest-rank percentiles of `v` (all zero when `v` is empty).
pub fn percentiles(v: &[f64]) -> Percentiles {
    if v.is_empty() {
        return Percentiles::default();
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let at = |q: f64| s[((q * s.len() as f64).ceil() as usize).clamp(1, s.len()) - 1];
    Percentiles { median_ms: at(0.5), p90_ms: at(0.9), p99_ms: at(0.99), max_ms: at(1.0) }
}

/// The element at index `len / 2` of the sorted values (0 when empty). For an even count this
/// is the upper of the two middle values, unlike [`percentiles`]' nearest-rank median (the
/// lower one); `summary.json`'s counter medians have always been computed this way.
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One column of the records.
pub fn column(frames: &[FrameRecord], f: impl Fn(&FrameRecord) -> f64) -> Vec<f64> {
    frames.iter().map(f).collect()
}

/// Percentiles of every stage timing, keyed as in `summary.json`'s `timing`: `load`,
/// `orb_left`, `orb_right`, `extract_wall`, `stereo`, `track`, `compute`, `total`, and
/// `segment` when `with_segment` (a network labelled the frames).
pub fn stage_percentiles(
    frames: &[FrameRecord],
    with_segment: bool,
) -> BTreeMap<&'static str, Percentiles> {
    let stage = |f: fn(&FrameRecord) -> f64| percentiles(&column(frames, f));
    let mut timing = BTreeMap::new();
    timing.insert("load", stage(|r| r.output.times.load_ms));
    timing.insert("orb_left", stage(|r| r.output.times.orb_left_ms));
    timing.insert("orb_right", stage(|r| r.output.times.orb_right_ms));
    timing.insert("extract_wall", stage(|r| r.output.times.extract_wall_ms));
    timing.insert("stereo", stage(|r| r.output.times.stereo_ms));
    timing.insert("track", stage(|r| r.output.times.track_ms));
    if with_segment {
        timing.insert("segment", stage(|r| r.output.times.seg_ms));
    }
    timing.insert("compute", stage(|r| r.output.times.compute_ms));
    timing.insert("total", stage(|r| r.output.times.total_ms));
    timing
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank() {
        let v: Vec<f64> = (1..=100).rev().map(f64::from).collect();
        let p = percentiles(&v);
        assert_eq!((p.median_ms, p.p90_ms, p.p99_ms, p.max_ms), (50.0, 90.0, 99.0, 100.0));
        assert_eq!(percentiles(&[]), Percentiles::default());
        let p = percentiles(&[3.0]);
        assert_eq!((p.median_ms, p.max_ms), (3.0, 3.0));
    }

    #[test]
    fn median_takes_the_upper_middle() {
        assert_eq!(median(vec![4.0, 1.0, 3.0, 2.0]), 3.0);
        assert_eq!(median(vec![2.0, 1.0, 3.0]), 2.0);
        assert_eq!(median(Vec::new()), 0.0);
        // percentiles' median of the same values is the lower middle
        assert_eq!(percentiles(&[4.0, 1.0, 3.0, 2.0]).median_ms, 2.0);
    }
}
