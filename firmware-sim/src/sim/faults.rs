//! Seeded, deterministic fault injection: what the sensor and the flash may do wrong.
//!
//! A spec is a comma-separated list of items (`--faults SPEC --seed N`):
//!
//! | item | effect |
//! |---|---|
//! | `drop@K` | the sensor never delivers frame K |
//! | `dup@K` | frame K carries frame K−1's images again (stuck buffer), with its own timestamp |
//! | `blank@K` | frame K is all zeros (both images) |
//! | `noise@K` | frame K is uniform noise (both images, independent) |
//! | `truncate@K` | the left transfer of frame K stops half-way |
//! | `desync@K[:D]` | frame K's right image is frame K−D's (default D = 3) |
//! | `jump@K:S` | from frame K on the sensor clock is off by S seconds (`+2`, `-0.5`) |
//! | `jitter:MS` | every timestamp gets uniform noise of ±MS milliseconds |
//! | `bitflip:N` | N random bits of the network blob are flipped before it is loaded |
//!
//! Instead of `@K` a per-frame kind takes `~P`: each frame independently with probability P
//! (`drop~0.05`). Every random choice comes from one xorshift64* stream seeded by `--seed`, drawn
//! in a fixed order, so a spec and a seed give the same faults on every run and machine.

use core::fmt;

/// One kind of fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FaultKind {
    /// The frame never arrives.
    Drop,
    /// The previous frame's images again.
    Duplicate,
    /// All-zero images.
    Blank,
    /// Noise images.
    Noise,
    /// Left buffer cut short.
    Truncate,
    /// Right image from another frame.
    Desync,
    /// Sensor clock jumps forward.
    JumpForward,
    /// Sensor clock jumps backwards.
    JumpBack,
    /// Timestamp noise on every frame.
    Jitter,
    /// Bits flipped in the model blob.
    BitFlip,
}

impl FaultKind {
    /// Every kind, in report order.
    pub const ALL: [FaultKind; 10] = [
        Self::Drop,
        Self::Duplicate,
        Self::Blank,
        Self::Noise,
        Self::Truncate,
        Self::Desync,
        Self::JumpForward,
        Self::JumpBack,
        Self::Jitter,
        Self::BitFlip,
    ];

    /// Flag of this kind in [`super::ring::SlotMeta::injected`].
    pub const fn bit(self) -> u16 {
        1 << self as u16
    }

    /// Name as in the spec.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Drop => "drop",
            Self::Duplicate => "dup",
            Self::Blank => "blank",
            Self::Noise => "noise",
            Self::Truncate => "truncate",
            Self::Desync => "desync",
            Self::JumpForward => "jump+",
            Self::JumpBack => "jump-",
            Self::Jitter => "jitter",
            Self::BitFlip => "bitflip",
        }
    }
}

impl fmt::Display for FaultKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// When a per-frame fault fires.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum When {
    /// On this sensor frame.
    At(u32),
    /// On each frame with this probability.
    Rate(f64),
}

/// One per-frame item of a spec.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultItem {
    /// What.
    pub kind: FaultKind,
    /// When.
    pub when: When,
    /// Desync: frame offset; jump: seconds.
    pub param: f64,
}

/// A parsed `--faults` spec.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FaultSpec {
    /// Per-frame items in spec order.
    pub items: Vec<FaultItem>,
    /// Timestamp jitter amplitude (s), 0 for none.
    pub jitter_s: f64,
    /// Bits to flip in the model blob.
    pub bitflips: u32,
}

/// A spec that does not parse: the item and the problem.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FaultSpecError {
    /// The offending item.
    pub item: String,
    /// What is wrong with it.
    pub problem: &'static str,
}

impl fmt::Display for FaultSpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "fault spec item `{}`: {}", self.item, self.problem)
    }
}

impl core::error::Error for FaultSpecError {}

impl core::str::FromStr for FaultSpec {
    type Err = FaultSpecError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let mut out = FaultSpec::default();
        for raw in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let err = |problem| FaultSpecError { item: raw.to_string(), problem };
            let (head, param) = match raw.split_once(':') {
                Some((h, p)) => (h, Some(p)),
                None => (raw, None),
            };
            let num = |p: Option<&str>| -> Result<Option<f64>, FaultSpecError> {
                p.map(|t| {
                    t.parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| err("parameter is not a finite number"))
                })
                .transpose()
            };
            let (name, when) = if let Some((n, k)) = head.split_once('@') {
                (n, Some(When::At(k.parse().map_err(|_| err("frame after `@` is not a number"))?)))
            } else if let Some((n, p)) = head.split_once('~') {
                let p: f64 = p.parse().map_err(|_| err("rate after `~` is not a number"))?;
                if !(0.0..=1.0).contains(&p) {
                    return Err(err("rate must be in [0, 1]"));
                }
                (n, Some(When::Rate(p)))
            } else {
                (head, None)
            };
            let per_frame = |kind, default: f64| -> Result<FaultItem, FaultSpecError> {
                let when = when.ok_or_else(|| err("needs `@FRAME` or `~RATE`"))?;
                Ok(FaultItem { kind, when, param: num(param)?.unwrap_or(default) })
            };
            match name {
                "drop" => out.items.push(per_frame(FaultKind::Drop, 0.0)?),
                "dup" => out.items.push(per_frame(FaultKind::Duplicate, 0.0)?),
                "blank" => out.items.push(per_frame(FaultKind::Blank, 0.0)?),
                "noise" => out.items.push(per_frame(FaultKind::Noise, 0.0)?),
                "truncate" => out.items.push(per_frame(FaultKind::Truncate, 0.0)?),
                "desync" => {
                    let it = per_frame(FaultKind::Desync, 3.0)?;
                    if it.param < 1.0 || it.param.fract() != 0.0 {
                        return Err(err("desync offset must be a whole number of frames >= 1"));
                    }
                    out.items.push(it);
                }
                "jump" => {
                    let it = per_frame(FaultKind::JumpForward, f64::NAN)?;
                    if it.param.is_nan() || it.param == 0.0 {
                        return Err(err("needs `:SECONDS`, non-zero (e.g. `jump@20:+2`)"));
                    }
                    let kind =
                        if it.param > 0.0 { FaultKind::JumpForward } else { FaultKind::JumpBack };
                    out.items.push(FaultItem { kind, ..it });
                }
                "jitter" | "bitflip" => {
                    if when.is_some() {
                        return Err(err("applies to the whole run: no `@` or `~`"));
                    }
                    let v = num(param)?.ok_or_else(|| err("needs `:VALUE`"))?;
                    if v < 0.0 {
                        return Err(err("must not be negative"));
                    }
                    if name == "jitter" {
                        out.jitter_s = v * 1e-3;
                    } else {
                        out.bitflips = v as u32;
                    }
                }
                _ => return Err(err("unknown fault kind")),
            }
        }
        Ok(out)
    }
}

impl FaultSpec {
    /// No faults.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty() && self.jitter_s == 0.0 && self.bitflips == 0
    }
}

/// xorshift64* (Vigna): tiny, seeded, the same numbers everywhere.
#[derive(Clone, Copy, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A stream from `seed` (any value; 0 is remapped).
    pub fn new(seed: u64) -> Self {
        Self((seed ^ 0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Fills `out` with random bytes.
    pub fn fill(&mut self, out: &mut [u8]) {
        for chunk in out.chunks_mut(8) {
            let b = self.next_u64().to_le_bytes();
            chunk.copy_from_slice(&b[..chunk.len()]);
        }
    }
}

/// What the sensor does to one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FramePlan {
    /// Injected kinds ([`FaultKind::bit`] flags).
    pub injected: u16,
    /// Right image taken from this many frames earlier.
    pub desync_frames: u32,
    /// Added to the true timestamp (jumps so far plus jitter), s.
    pub clock_offset_s: f64,
    /// The jitter part of `clock_offset_s` (s).
    pub jitter_s: f64,
}

impl FramePlan {
    /// Whether `kind` was injected.
    pub fn has(&self, kind: FaultKind) -> bool {
        self.injected & kind.bit() != 0
    }
}

/// Draws the per-frame faults of a spec, frame after frame.
#[derive(Clone, Debug)]
pub struct Injector {
    spec: FaultSpec,
    rng: Rng,
    clock_offset_s: f64,
}

impl Injector {
    /// An injector for `spec` seeded with `seed`.
    pub fn new(spec: FaultSpec, seed: u64) -> Self {
        Self { spec, rng: Rng::new(seed), clock_offset_s: 0.0 }
    }

    /// The random stream (noise images draw from it, after the frame's plan).
    pub fn rng(&mut self) -> &mut Rng {
        &mut self.rng
    }

    /// The plan of sensor frame `k` (call once per frame, in order). No allocation.
    pub fn plan(&mut self, k: u32) -> FramePlan {
        let mut p = FramePlan::default();
        for it in &self.spec.items {
            let fire = match it.when {
                When::At(f) => f == k,
                When::Rate(r) => self.rng.unit() < r,
            };
            // The first frame carries no fault: it builds the first map.
            if !fire || k == 0 {
                continue;
            }
            p.injected |= it.kind.bit();
            match it.kind {
                FaultKind::Desync => p.desync_frames = (it.param as u32).min(k),
                FaultKind::JumpForward | FaultKind::JumpBack => self.clock_offset_s += it.param,
                _ => {}
            }
        }
        p.clock_offset_s = self.clock_offset_s;
        if self.spec.jitter_s > 0.0 {
            p.jitter_s = (2.0 * self.rng.unit() - 1.0) * self.spec.jitter_s;
            p.clock_offset_s += p.jitter_s;
        }
        p
    }
}

/// Flips `n` seeded random bits of `blob` (the model's image in RAM, before it is loaded);
/// returns the byte offsets flipped.
pub fn flip_bits(blob: &mut [u8], n: u32, seed: u64) -> Vec<usize> {
    let mut rng = Rng::new(seed ^ 0xB17F_11B5);
    let mut at = Vec::with_capacity(n as usize);
    if blob.is_empty() {
        return at;
    }
    for _ in 0..n {
        let bit = rng.next_u64() % (blob.len() as u64 * 8);
        blob[(bit / 8) as usize] ^= 1 << (bit % 8);
        at.push((bit / 8) as usize);
    }
    at
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_kind_and_rejects_nonsense() {
        let s: FaultSpec =
            "drop@5, dup@8,blank@10,noise~0.5,truncate@14,desync@16:2,jump@20:+2,jump@25:-0.5,\
             jitter:5,bitflip:3"
                .parse()
                .unwrap();
        assert_eq!(s.items.len(), 8);
        assert_eq!(
            s.items[5],
            FaultItem { kind: FaultKind::Desync, when: When::At(16), param: 2.0 }
        );
        assert_eq!(s.items[7].kind, FaultKind::JumpBack);
        assert_eq!(s.items[3].when, When::Rate(0.5));
        assert!((s.jitter_s - 0.005).abs() < 1e-12);
        assert_eq!(s.bitflips, 3);
        for bad in ["drop", "fire@3", "drop@x", "drop~2", "jump@3", "jitter@3:1", "desync@3:0"] {
            let e = bad.parse::<FaultSpec>().unwrap_err();
            assert!(e.to_string().contains(bad), "{e}");
        }
        assert!("".parse::<FaultSpec>().unwrap().is_empty());
    }

    #[test]
    fn plans_are_seeded_and_deterministic() {
        let spec: FaultSpec = "drop~0.3,jitter:10,jump@4:+1".parse().unwrap();
        let run = |seed| {
            let mut inj = Injector::new(spec.clone(), seed);
            (0..50).map(|k| inj.plan(k)).collect::<Vec<_>>()
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7), run(8));
        let p = run(7);
        assert_eq!(p[0].injected, 0, "frame 0 is clean");
        assert!(p.iter().all(|q| q.clock_offset_s.abs() <= 1.0 + 0.01));
        assert!(p[5].clock_offset_s > 0.98 && p[3].clock_offset_s.abs() <= 0.01);
        let drops = p.iter().filter(|q| q.has(FaultKind::Drop)).count();
        assert!((5..=25).contains(&drops), "{drops}");
    }

    #[test]
    fn bit_flips_are_seeded() {
        let mut a = vec![0u8; 100];
        let at = flip_bits(&mut a, 3, 1);
        assert_eq!(at.len(), 3);
        assert!(a.iter().map(|b| b.count_ones()).sum::<u32>() <= 3);
        let mut b = vec![0u8; 100];
        flip_bits(&mut b, 3, 1);
        assert_eq!(a, b);
    }
}
