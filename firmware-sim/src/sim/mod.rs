//! # ECU simulation (std feature)
//!
//! Runs the [`Localiser`] the way an ECU task would, on the host:
//!
//! * **Fixed state, built once.** Everything the loop touches is allocated at start-up: the
//!   localiser (boxed, ≈ 41 MiB), the segmentation buffers (network arena, input and label
//!   maps, weight image), the frame ring's slots, the per-frame record table. After start-up
//!   the ECU part of the loop allocates nothing; with a counting global allocator (the
//!   `ecu-sim` binary and the tests install `stats_alloc`) the count is measured and reported.
//! * **Simulated sensor clock.** Frame `k` arrives at `k · period` (default 100 ms, 10 Hz) of
//!   simulated time into a bounded [`ring::FrameRing`]; a frame arriving while the ring is full
//!   is dropped and counted. The ECU takes the oldest frame when it is free; a frame's cost on
//!   the simulated clock is its measured wall time × `cpu_scale` (1 = this host; > 1 models a
//!   slower ECU core). The sensor's work (PNG decoding for KITTI) is outside the timed region.
//! * **Deadline.** A frame whose cost exceeds `budget` (default 100 ms) is a deadline miss;
//!   the next frame runs [`health::Mode::Degraded`] (reuse the last labels, drop stale queued
//!   frames), then the ECU returns to nominal. Reported: worst case, p50/p90/p99, misses,
//!   degraded frames, ring drops, state size, high-water marks, a stack estimate.
//! * **Faults** ([`faults`]): injected by the sensor side, seeded; the ECU only sees their
//!   effects and must detect them ([`health`]), never panic, and recover. Per injected fault
//!   the report gives the detection and the recovery time in frames.
//!
//! Model blob corruption (`bitflip:N`): the blob's CRC-32 makes loading fail with a typed
//! error ([`crate::LocaliserError::Model`] with `ModelError::BadChecksum`). The simulation then
//! runs **geometric-only** (limp-home: localisation without the network), says so in the
//! report, and [`SimReport::semantics_error`] holds the error; `strict_model` makes it refuse
//! to start instead.

pub mod faults;
pub mod health;
pub mod ring;
pub mod source;

use core::fmt;
use std::path::PathBuf;
use std::time::Instant;

use semloc_core::tracker::TrackState;

use crate::report::pose_row;
use crate::{
    geometric_params, semantic_params, Localiser, LocaliserConfig, LocaliserError, Network,
    NetworkMemory, SEMANTIC_SCHEME,
};
use faults::{FaultKind, FaultSpec, Injector};
use health::{ClockAction, Detection, HealthParams, Mode, Monitor};
use ring::{FrameRing, Slot};
use source::FrameSource;

/// Why the simulation could not run. Bad input frames are not errors (they are detected and
/// reported); these are problems with the setup.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum SimError {
    /// The frame source (dataset folder, file) failed.
    Source {
        /// The file or folder.
        path: PathBuf,
        /// What went wrong.
        problem: String,
    },
    /// The network blob could not be read or loaded (and `strict_model` was set).
    Model {
        /// The blob's file (or `embedded`).
        path: PathBuf,
        /// What went wrong.
        problem: String,
    },
    /// The localiser could not be built.
    Localiser(LocaliserError),
    /// The configuration is unusable.
    Config(String),
    /// The simulation thread could not be started or panicked.
    Worker,
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Source { path, problem } => write!(f, "{}: {problem}", path.display()),
            Self::Model { path, problem } => {
                write!(f, "{}: {problem}; refusing to start (strict model)", path.display())
            }
            Self::Localiser(e) => write!(f, "localiser: {e}"),
            Self::Config(m) => write!(f, "configuration: {m}"),
            Self::Worker => f.write_str("simulation thread failed"),
        }
    }
}

impl core::error::Error for SimError {}

/// Where the network comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelSource {
    /// The blob compiled into this crate (`models/artefacts/fastscnn_r2_192x640.slm`).
    Embedded,
    /// A `.slm` file.
    File(PathBuf),
}

/// Simulation settings.
#[derive(Clone, Debug)]
pub struct SimConfig {
    /// Sensor period (s).
    pub period_s: f64,
    /// Per-frame deadline (s of simulated ECU time).
    pub budget_s: f64,
    /// Frame ring slots.
    pub ring_capacity: usize,
    /// Simulated ECU time per second of host wall time.
    pub cpu_scale: f64,
    /// Run the network and the semantic pipeline (else geometric).
    pub semantics: bool,
    /// The network.
    pub model: ModelSource,
    /// Refuse to start when the network does not load (default: run geometric-only).
    pub strict_model: bool,
    /// Faults to inject.
    pub faults: FaultSpec,
    /// Seed of the fault injection.
    pub seed: u64,
    /// Health check thresholds.
    pub health: HealthParams,
    /// Apply the degradation policy after overruns.
    pub degrade: bool,
    /// At most this many sensor frames (default: the whole source).
    pub max_frames: Option<usize>,
    /// Allocation counter (allocations + reallocations so far, process-wide), when a counting
    /// global allocator is installed.
    pub alloc_counter: Option<fn() -> u64>,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            period_s: 0.1,
            budget_s: 0.1,
            ring_capacity: 4,
            cpu_scale: 1.0,
            semantics: false,
            model: ModelSource::Embedded,
            strict_model: false,
            faults: FaultSpec::default(),
            seed: 0,
            health: HealthParams::default(),
            degrade: true,
            max_frames: None,
            alloc_counter: None,
        }
    }
}

/// Stack reserved for the simulation thread (virtual; only touched pages are used): the
/// localiser's constructor returns ≈ 41 MiB by value and peaks at a few times that on aarch64
/// (see the crate README); unoptimised host builds move the value a few more times.
pub const SIM_STACK_BYTES: usize = 1 << 30;

/// Peak stack of one frame, measured on the bare-metal aarch64 image by painting its stack
/// (`qemu-check.sh`, `@ … pass` lines: 14,704 bytes): geometric pipeline.
pub const FRAME_STACK_GEOMETRIC_BYTES: usize = 14_800;
/// The same with the network and the semantic pipeline (18,352 bytes on a Cortex-A72, 19,216 on
/// an A76: the 1×1 GEMMs' staged rows and requantisers, 13-14 KiB, are the deepest frame).
/// `qemu-check.sh` fails when either measures more than this or the geometric constant.
pub const FRAME_STACK_SEMANTIC_BYTES: usize = 19_300;

/// One processed (or rejected) frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameRecord {
    /// Sensor frame number.
    pub sensor_index: u32,
    /// Simulated arrival, start and finish (s).
    pub arrival_s: f64,
    /// Processing start (s, simulated).
    pub start_s: f64,
    /// Processing end (s, simulated).
    pub finish_s: f64,
    /// Cost on the simulated ECU (ms): wall time × `cpu_scale`.
    pub exec_ms: f64,
    /// Mode the frame ran in.
    pub mode: Mode,
    /// Whether the network ran on this frame.
    pub labelled: bool,
    /// Faults the sensor injected ([`FaultKind::bit`] flags).
    pub injected: u16,
    /// What the ECU detected ([`Detection::bit`] flags).
    pub detections: u16,
    /// The frame reached the tracker.
    pub tracked: bool,
    /// Tracker state after the frame.
    pub state: TrackState,
    /// Tracker inliers.
    pub inliers: u32,
    /// Left key points.
    pub features: u32,
    /// Stereo matches.
    pub stereo_matched: u32,
    /// Tracked with enough inliers, not (re-)initialised: see [`health`].
    pub good: bool,
    /// Pose `t_wc` after the frame (KITTI row).
    pub t_wc: [f64; 12],
}

impl FrameRecord {
    /// Whether `d` was detected on this frame.
    pub fn detected(&self, d: Detection) -> bool {
        self.detections & d.bit() != 0
    }
}

/// One injected fault and what became of it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultEvent {
    /// The fault.
    pub kind: FaultKind,
    /// Sensor frame it hit.
    pub frame: u32,
    /// First detection within two frames of it: (frame, detection).
    pub detected: Option<(u32, Detection)>,
    /// First good frame at or after it.
    pub recovered_at: Option<u32>,
}

impl FaultEvent {
    /// Sensor frames from the fault to the first good frame.
    pub fn recovery_frames(&self) -> Option<u32> {
        self.recovered_at.map(|g| g - self.frame)
    }
}

/// Order statistics of the frame costs (ms).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timing {
    /// Worst case.
    pub max_ms: f64,
    /// Median.
    pub p50_ms: f64,
    /// 90th percentile.
    pub p90_ms: f64,
    /// 99th percentile.
    pub p99_ms: f64,
    /// Mean.
    pub mean_ms: f64,
}

impl Timing {
    /// Nearest-rank percentiles of `ms` (sorted in place).
    pub fn of(ms: &mut [f64]) -> Self {
        if ms.is_empty() {
            return Self::default();
        }
        ms.sort_unstable_by(f64::total_cmp);
        let at = |p: f64| ms[((p * ms.len() as f64).ceil() as usize).clamp(1, ms.len()) - 1];
        Self {
            max_ms: ms[ms.len() - 1],
            p50_ms: at(0.5),
            p90_ms: at(0.9),
            p99_ms: at(0.99),
            mean_ms: ms.iter().sum::<f64>() / ms.len() as f64,
        }
    }
}

/// Fixed memory of the simulation (bytes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StateSize {
    /// The localiser (extractors, matcher, frame, tracker).
    pub localiser: usize,
    /// Segmentation buffers (arena, maps, weights), 0 geometric.
    pub segmentation: usize,
    /// Network activation arena actually needed (of `segmentation`).
    pub network_arena_used: usize,
    /// Frame ring slots.
    pub ring: usize,
    /// Per-frame record table.
    pub records: usize,
}

impl StateSize {
    /// Everything.
    pub fn total(&self) -> usize {
        self.localiser + self.segmentation + self.ring + self.records
    }
}

/// High-water marks over the run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HighWater {
    /// Frames waiting in the ring at once (of its capacity).
    pub ring: usize,
    /// Left key points in a frame (of `FRAME_CAPACITY`).
    pub features: u32,
    /// Live landmarks (of `MAX_LANDMARKS`).
    pub landmarks: u32,
    /// Keyframes in the window (of `MAX_KEYFRAMES`).
    pub keyframes: u32,
}

/// What a simulation run measured.
#[derive(Clone, Debug, PartialEq)]
pub struct SimReport {
    /// The source's name.
    pub source: String,
    /// Frame size.
    pub size: (usize, usize),
    /// Semantic pipeline requested.
    pub semantics_requested: bool,
    /// Semantic pipeline ran (false when the network did not load).
    pub semantics: bool,
    /// Why the network is off although requested (the typed load error, with the file).
    pub semantics_error: Option<String>,
    /// Settings.
    pub period_s: f64,
    /// Budget (s).
    pub budget_s: f64,
    /// Host → ECU time scale.
    pub cpu_scale: f64,
    /// Ring slots.
    pub ring_capacity: usize,
    /// Sensor frames generated.
    pub sensor_frames: u32,
    /// Frames the ECU processed (including rejected ones).
    pub processed: u32,
    /// Frames that reached the tracker.
    pub tracked: u32,
    /// Good frames.
    pub good: u32,
    /// Rejected frames.
    pub rejected: u32,
    /// Tracking losses.
    pub lost: u32,
    /// Frame costs.
    pub timing: Timing,
    /// Frames over budget.
    pub deadline_misses: u32,
    /// Frames run degraded.
    pub degraded_frames: u32,
    /// Degraded frames that reused the last labels.
    pub labels_reused: u32,
    /// Frames dropped from the ring by the catch-up.
    pub stale_dropped: u32,
    /// Frames dropped because the ring was full.
    pub ring_overflow_drops: u32,
    /// Frames the sensor never delivered (`drop` faults).
    pub sensor_drops: u32,
    /// Longest arrival → finish latency (ms, simulated).
    pub max_latency_ms: f64,
    /// Fixed state.
    pub state: StateSize,
    /// High-water marks.
    pub high_water: HighWater,
    /// Stack estimate per frame (bytes): the bare-metal measurement.
    pub frame_stack_bytes: usize,
    /// Stack reserved for the simulation thread (construction).
    pub thread_stack_bytes: usize,
    /// Allocations in the ECU part of the loop after start-up (None without a counter).
    pub ecu_allocations: Option<u64>,
    /// Allocations of the sensor side after start-up (decoding PNGs), for information.
    pub sensor_allocations: Option<u64>,
    /// Per-detection counts, in [`Detection::ALL`] order.
    pub detections: [u32; 10],
    /// Injected faults.
    pub faults: Vec<FaultEvent>,
    /// Largest timestamp disturbance injected by jitter (ms).
    pub max_jitter_ms: f64,
    /// Model bits flipped at load (byte offsets).
    pub bitflips_at: Vec<usize>,
    /// Per processed frame.
    pub frames: Vec<FrameRecord>,
}

impl SimReport {
    /// Count of detection `d`.
    pub fn detections_of(&self, d: Detection) -> u32 {
        self.detections[Detection::ALL.iter().position(|&x| x == d).unwrap_or(0)]
    }

    /// Injected faults of `kind`.
    pub fn faults_of(&self, kind: FaultKind) -> impl Iterator<Item = &FaultEvent> {
        self.faults.iter().filter(move |e| e.kind == kind)
    }

    /// The run is healthy at its end: the last processed frame was good.
    pub fn ends_good(&self) -> bool {
        self.frames.last().is_some_and(|f| f.good)
    }
}

impl fmt::Display for SimReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mib = |b: usize| b as f64 / (1u64 << 20) as f64;
        writeln!(f, "# semloc ECU simulation")?;
        writeln!(f, "source            {} ({}x{})", self.source, self.size.0, self.size.1)?;
        let pipeline = match (&self.semantics_error, self.semantics) {
            (Some(e), _) => format!("GEOMETRIC-ONLY (limp-home): network not loaded: {e}"),
            (None, true) => "semantic (int8 network, semantic ORB, EM)".to_string(),
            (None, false) => "geometric (ORB, stereo, tracker)".to_string(),
        };
        writeln!(f, "pipeline          {pipeline}")?;
        writeln!(
            f,
            "clock             period {:.0} ms, budget {:.1} ms, cpu_scale {}, ring {} slots",
            self.period_s * 1e3,
            self.budget_s * 1e3,
            self.cpu_scale,
            self.ring_capacity
        )?;
        writeln!(
            f,
            "frames            sensor {} processed {} tracked {} good {} rejected {} lost {}",
            self.sensor_frames, self.processed, self.tracked, self.good, self.rejected, self.lost
        )?;
        let t = &self.timing;
        writeln!(
            f,
            "exec time (ms)    WCET {:.2} p50 {:.2} p90 {:.2} p99 {:.2} mean {:.2}  (budget {:.1}: WCET/budget {:.2})",
            t.max_ms,
            t.p50_ms,
            t.p90_ms,
            t.p99_ms,
            t.mean_ms,
            self.budget_s * 1e3,
            t.max_ms / (self.budget_s * 1e3)
        )?;
        writeln!(
            f,
            "deadline          misses {} degraded frames {} (labels reused {}, stale dropped {}); max latency {:.1} ms",
            self.deadline_misses,
            self.degraded_frames,
            self.labels_reused,
            self.stale_dropped,
            self.max_latency_ms
        )?;
        writeln!(
            f,
            "drops             ring overflow {} sensor {}",
            self.ring_overflow_drops, self.sensor_drops
        )?;
        let s = &self.state;
        writeln!(
            f,
            "state (MiB)       total {:.2}: localiser {:.2} segmentation {:.2} (network arena used {:.2}) ring {:.2} records {:.3}",
            mib(s.total()),
            mib(s.localiser),
            mib(s.segmentation),
            mib(s.network_arena_used),
            mib(s.ring),
            mib(s.records)
        )?;
        let h = &self.high_water;
        writeln!(
            f,
            "high water        ring {}/{} features {}/{} landmarks {}/{} keyframes {}/{}",
            h.ring,
            self.ring_capacity,
            h.features,
            semloc_core::frame::FRAME_CAPACITY,
            h.landmarks,
            semloc_core::map::MAX_LANDMARKS,
            h.keyframes,
            semloc_core::map::MAX_KEYFRAMES
        )?;
        writeln!(
            f,
            "stack             ≈ {:.1} KB per frame (bare-metal aarch64 measurement); {} MiB thread for construction",
            self.frame_stack_bytes as f64 / 1e3,
            self.thread_stack_bytes >> 20
        )?;
        let opt = |a: Option<u64>| a.map_or("not counted".to_string(), |n| n.to_string());
        writeln!(
            f,
            "allocations       after start-up: ECU {} (sensor side {})",
            opt(self.ecu_allocations),
            opt(self.sensor_allocations)
        )?;
        write!(f, "detections       ")?;
        for (d, n) in Detection::ALL.iter().zip(self.detections) {
            if n > 0 {
                write!(f, " {d} {n}")?;
            }
        }
        writeln!(f)?;
        if !self.bitflips_at.is_empty() {
            writeln!(f, "model bit flips   at bytes {:?}", self.bitflips_at)?;
        }
        if self.max_jitter_ms > 0.0 {
            writeln!(
                f,
                "jitter            max {:.1} ms (tolerated below {:.0} % of a period)",
                self.max_jitter_ms, 50.0
            )?;
        }
        if !self.faults.is_empty() {
            writeln!(f, "faults            kind frame detected(frame) recovery(frames)")?;
            for e in &self.faults {
                let det = e.detected.map_or("UNDETECTED".to_string(), |(k, d)| format!("{d}({k})"));
                let rec =
                    e.recovery_frames().map_or("NOT RECOVERED".to_string(), |r| r.to_string());
                writeln!(f, "                  {} {} {det} {rec}", e.kind, e.frame)?;
            }
        }
        write!(
            f,
            "end               {}",
            if self.ends_good() { "tracking good" } else { "NOT tracking" }
        )
    }
}

/// The network blob in RAM, 16-byte aligned, possibly with flipped bits.
struct Blob {
    buf: Vec<u8>,
    off: usize,
    len: usize,
    path: PathBuf,
}

impl Blob {
    fn load(src: &ModelSource) -> Result<Self, SimError> {
        let (bytes, path) = match src {
            ModelSource::Embedded => {
                (crate::embedded::MODEL_BLOB.to_vec(), PathBuf::from("embedded"))
            }
            ModelSource::File(p) => (
                std::fs::read(p).map_err(|e| SimError::Model {
                    path: p.clone(),
                    problem: format!("cannot read: {e}"),
                })?,
                p.clone(),
            ),
        };
        let mut buf = vec![0u8; bytes.len() + 16];
        let off = buf.as_ptr().align_offset(16).min(16);
        buf[off..off + bytes.len()].copy_from_slice(&bytes);
        Ok(Self { buf, off, len: bytes.len(), path })
    }

    fn bytes(&self) -> &[u8] {
        &self.buf[self.off..self.off + self.len]
    }

    fn bytes_mut(&mut self) -> &mut [u8] {
        &mut self.buf[self.off..self.off + self.len]
    }
}

/// Runs the simulation over `source` (on a thread with [`SIM_STACK_BYTES`] of stack).
///
/// # Errors
/// [`SimError`] for setup problems (source, network with `strict_model`, localiser); bad
/// frames are detected and reported, never errors.
pub fn run(source: &mut dyn FrameSource, cfg: &SimConfig) -> Result<SimReport, SimError> {
    std::thread::scope(|s| {
        std::thread::Builder::new()
            .name("ecu-sim".into())
            .stack_size(SIM_STACK_BYTES)
            .spawn_scoped(s, || run_here(source, cfg))
            .map_err(|_| SimError::Worker)?
            .join()
            .map_err(|_| SimError::Worker)?
    })
}

/// The segmentation buffers for `w`x`h` frames, built once.
struct SegBufs {
    arena: Vec<i8>,
    input: Vec<u8>,
    model_labels: Vec<u8>,
}

impl SegBufs {
    fn bytes(&self) -> usize {
        self.arena.len() + self.input.len() + self.model_labels.len()
    }
}

fn run_here(source: &mut dyn FrameSource, cfg: &SimConfig) -> Result<SimReport, SimError> {
    if !(cfg.period_s > 0.0 && cfg.budget_s > 0.0 && cfg.cpu_scale > 0.0) {
        return Err(SimError::Config("period, budget and cpu_scale must be positive".into()));
    }
    let (w, h) = source.size();
    let n = cfg.max_frames.map_or(source.len(), |m| m.min(source.len()));
    if n == 0 {
        return Err(SimError::Source {
            path: PathBuf::from(source.name()),
            problem: "no frames".into(),
        });
    }
    let cam = source.camera()?;
    let frame_bytes = w * h;

    // ---- start-up: every buffer the loop uses ----
    let mut blob = if cfg.semantics { Some(Blob::load(&cfg.model)?) } else { None };
    let mut bitflips_at = Vec::new();
    if let Some(b) = blob.as_mut() {
        if cfg.faults.bitflips > 0 {
            bitflips_at = faults::flip_bits(b.bytes_mut(), cfg.faults.bitflips, cfg.seed);
        }
    }
    // Parse once for the buffer sizes; a corrupt blob fails here with its typed error.
    let mut semantics_error = None;
    let mut seg_bufs = None;
    let mut arena_used = 0;
    if let Some(b) = blob.as_ref() {
        match semloc_core::nn::model::Model::parse(b.bytes()) {
            Ok(m) => {
                let (mh, mw) = m.input_size();
                arena_used = m.arena_len();
                seg_bufs = Some(SegBufs {
                    arena: vec![0i8; crate::SEG_ARENA_BYTES.max(m.arena_len())],
                    input: vec![0u8; mh * mw],
                    model_labels: vec![0u8; mh * mw],
                });
            }
            Err(e) => {
                semantics_error =
                    Some(format!("{}: {}", b.path.display(), LocaliserError::Model(e)))
            }
        }
    }
    let seg_bytes = seg_bufs.as_ref().map_or(0, SegBufs::bytes);
    let mut sem = match (seg_bufs.as_mut(), blob.as_ref()) {
        (Some(sb), Some(b)) => {
            let mem = NetworkMemory {
                arena: &mut sb.arena,
                input: &mut sb.input,
                model_labels: &mut sb.model_labels,
            };
            match Network::new(b.bytes(), w, h, mem) {
                Ok(s) => Some(s),
                Err(e) => {
                    semantics_error = Some(format!("{}: {e}", b.path.display()));
                    None
                }
            }
        }
        _ => None,
    };
    if let (Some(e), true) = (&semantics_error, cfg.strict_model) {
        let path = blob.as_ref().map_or_else(PathBuf::new, |b| b.path.clone());
        let problem = e.strip_prefix(&format!("{}: ", path.display())).unwrap_or(e).to_string();
        return Err(SimError::Model { path, problem });
    }
    let config = LocaliserConfig {
        tracker: if sem.is_some() { semantic_params() } else { geometric_params() },
        semantics: sem.is_some().then_some(SEMANTIC_SCHEME),
        ..LocaliserConfig::new(cam, w as u32, h as u32)
    };
    let mut loc = Box::new(Localiser::new(&config).map_err(SimError::Localiser)?);
    let mut ring = FrameRing::new(cfg.ring_capacity, frame_bytes);
    let mut records: Vec<FrameRecord> = Vec::with_capacity(n);
    let mut exec: Vec<f64> = Vec::with_capacity(n);
    let mut events: Vec<FaultEvent> = Vec::with_capacity(n * 4 + 8);
    let mut injector = Injector::new(cfg.faults.clone(), cfg.seed);
    let state = StateSize {
        localiser: Localiser::MEMORY_BYTES,
        segmentation: seg_bytes,
        network_arena_used: arena_used,
        ring: ring.storage_bytes(),
        records: records.capacity() * core::mem::size_of::<FrameRecord>()
            + events.capacity() * core::mem::size_of::<FaultEvent>(),
    };

    let mut ecu = Ecu {
        loc: &mut loc,
        sem: sem.as_mut(),
        monitor: Monitor::new(cfg.health),
        mode: Mode::Nominal,
        have_labels: false,
        w,
        h,
        period_s: cfg.period_s,
        counters: Counters::default(),
        high: HighWater::default(),
    };
    let counter = cfg.alloc_counter;
    let count = || counter.map_or(0, |c| c());
    let (mut ecu_allocs, mut sensor_allocs) = (0u64, 0u64);
    let mut busy_until = 0.0f64;
    let mut max_latency_s = 0.0f64;
    let mut max_jitter_s = 0.0f64;
    let mut sensor_drops = 0u32;
    let mut last_img = 0usize;
    let mut stale_dropped = 0u32;

    // ---- the loop: sensor arrivals and ECU work on the simulated clock ----
    let mut k = 0usize;
    loop {
        let arrival = k as f64 * cfg.period_s;
        // The ECU works through the ring while it is free before the next arrival.
        while !ring.is_empty() {
            if k < n && busy_until > arrival {
                break;
            }
            let a0 = count();
            if ecu.mode == Mode::Degraded && cfg.degrade {
                stale_dropped += ring.drop_stale() as u32;
            }
            let Some(slot) = ring.front() else { break };
            let start = busy_until.max(slot.meta.arrival_s);
            let t0 = Instant::now();
            let mut rec = ecu.step(slot);
            let cost_s = t0.elapsed().as_secs_f64() * cfg.cpu_scale;
            ring.pop();
            let overran = cost_s > cfg.budget_s;
            ecu.counters.misses += u32::from(overran);
            ecu.mode = if cfg.degrade { ecu.mode.next(overran) } else { Mode::Nominal };
            busy_until = start + cost_s;
            rec.start_s = start;
            rec.finish_s = busy_until;
            rec.exec_ms = cost_s * 1e3;
            max_latency_s = max_latency_s.max(busy_until - rec.arrival_s);
            attribute(&mut events, &rec);
            if records.len() < records.capacity() {
                records.push(rec);
                exec.push(rec.exec_ms);
            }
            ecu_allocs += count() - a0;
        }
        if k >= n {
            break;
        }
        // The sensor: frame k arrives (or not).
        let a0 = count();
        let plan = injector.plan(k as u32);
        max_jitter_s = max_jitter_s.max(plan.jitter_s.abs());
        for kind in FaultKind::ALL {
            if plan.has(kind) && events.len() < events.capacity() {
                events.push(FaultEvent {
                    kind,
                    frame: k as u32,
                    detected: None,
                    recovered_at: None,
                });
            }
        }
        if plan.has(FaultKind::Drop) {
            sensor_drops += 1;
        } else {
            let ts = source.timestamp_s(k) + plan.clock_offset_s;
            let filled = ring.push_with(|slot: &mut Slot| -> Result<(), SimError> {
                slot.meta = ring::SlotMeta {
                    sensor_index: k as u32,
                    arrival_s: arrival,
                    timestamp_s: ts,
                    injected: plan.injected,
                };
                // A stuck buffer repeats what the sensor delivered last.
                let img = if plan.has(FaultKind::Duplicate) { last_img } else { k };
                last_img = img;
                source.load(img, false, &mut slot.left)?;
                let r =
                    if plan.has(FaultKind::Desync) { k - plan.desync_frames as usize } else { img };
                source.load(r, true, &mut slot.right)?;
                slot.left_len = frame_bytes;
                slot.right_len = frame_bytes;
                if plan.has(FaultKind::Blank) {
                    slot.left.fill(0);
                    slot.right.fill(0);
                }
                if plan.has(FaultKind::Noise) {
                    injector.rng().fill(&mut slot.left);
                    injector.rng().fill(&mut slot.right);
                }
                if plan.has(FaultKind::Truncate) {
                    slot.left_len = frame_bytes / 2;
                }
                Ok(())
            });
            if let Some(r) = filled {
                r?;
            }
        }
        sensor_allocs += count() - a0;
        k += 1;
    }
    ecu.high.ring = ring.high_water();
    let Ecu { counters: c, high, .. } = ecu;
    let mut detections = [0u32; 10];
    for r in &records {
        for (i, d) in Detection::ALL.iter().enumerate() {
            detections[i] += u32::from(r.detected(*d));
        }
    }
    let timing = Timing::of(&mut exec);
    Ok(SimReport {
        source: source.name(),
        size: (w, h),
        semantics_requested: cfg.semantics,
        semantics: sem.is_some(),
        semantics_error,
        period_s: cfg.period_s,
        budget_s: cfg.budget_s,
        cpu_scale: cfg.cpu_scale,
        ring_capacity: ring.capacity(),
        sensor_frames: n as u32,
        processed: records.len() as u32,
        tracked: records.iter().filter(|r| r.tracked).count() as u32,
        good: records.iter().filter(|r| r.good).count() as u32,
        rejected: records.iter().filter(|r| !r.tracked).count() as u32,
        lost: c.lost,
        timing,
        deadline_misses: c.misses,
        degraded_frames: c.degraded,
        labels_reused: c.labels_reused,
        stale_dropped,
        ring_overflow_drops: ring.overflow_drops(),
        sensor_drops,
        max_latency_ms: max_latency_s * 1e3,
        state,
        high_water: high,
        frame_stack_bytes: if sem.is_some() {
            FRAME_STACK_SEMANTIC_BYTES
        } else {
            FRAME_STACK_GEOMETRIC_BYTES
        },
        thread_stack_bytes: SIM_STACK_BYTES,
        ecu_allocations: counter.map(|_| ecu_allocs),
        sensor_allocations: counter.map(|_| sensor_allocs),
        detections,
        faults: events,
        max_jitter_ms: max_jitter_s * 1e3,
        bitflips_at,
        frames: records,
    })
}

/// Marks detections and recoveries on the fault events.
fn attribute(events: &mut [FaultEvent], rec: &FrameRecord) {
    let k = rec.sensor_index;
    for e in events.iter_mut().rev() {
        if e.frame > k {
            continue;
        }
        if e.detected.is_none() && rec.detections != 0 && k - e.frame <= 2 {
            let d = Detection::ALL.into_iter().find(|d| rec.detected(*d));
            e.detected = d.map(|d| (k, d));
        }
        if e.recovered_at.is_none() && rec.good {
            e.recovered_at = Some(k);
        }
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct Counters {
    misses: u32,
    degraded: u32,
    labels_reused: u32,
    lost: u32,
}

/// The ECU task: the localiser, the network stage, the health monitor, the mode.
struct Ecu<'l, 's> {
    loc: &'l mut Localiser,
    sem: Option<&'l mut Network<'s>>,
    monitor: Monitor,
    mode: Mode,
    have_labels: bool,
    w: usize,
    h: usize,
    period_s: f64,
    counters: Counters,
    high: HighWater,
}

impl Ecu<'_, '_> {
    /// One frame: checks, front end, checks, tracking. Never fails: problems are detections.
    fn step(&mut self, slot: &Slot) -> FrameRecord {
        let m = &slot.meta;
        let mut rec = FrameRecord {
            sensor_index: m.sensor_index,
            arrival_s: m.arrival_s,
            start_s: 0.0,
            finish_s: 0.0,
            exec_ms: 0.0,
            mode: self.mode,
            labelled: false,
            injected: m.injected,
            detections: 0,
            tracked: false,
            state: TrackState::Uninitialised,
            inliers: 0,
            features: 0,
            stereo_matched: 0,
            good: false,
            t_wc: [0.0; 12],
        };
        if self.mode == Mode::Degraded {
            self.counters.degraded += 1;
        }
        let (clock, action) = self.monitor.check_clock(m.timestamp_s, self.period_s);
        if let Some(d) = clock {
            rec.detections |= d.bit();
        }
        match action {
            ClockAction::None => {}
            ClockAction::Coast(n) => (0..n).for_each(|_| self.loc.coast()),
            ClockAction::ForgetMotion => self.loc.forget_motion(),
        }
        let reject = |rec: &mut FrameRecord, d: Detection, loc: &mut Localiser| {
            rec.detections |= d.bit();
            loc.coast();
            rec.t_wc = pose_row(&loc.tracker().pose_wc());
        };
        if let Some(d) =
            self.monitor.check_images(slot.left(), slot.right(), self.w, self.w * self.h)
        {
            reject(&mut rec, d, self.loc);
            return rec;
        }
        let relabel = !(self.mode == Mode::Degraded && self.have_labels);
        let ts = m.timestamp_s;
        // Degraded: no network run, the last labels are reused.
        let network = if relabel { self.sem.as_deref_mut() } else { None };
        let front = self.loc.front_end(slot.left(), slot.right(), ts, network);
        if self.sem.is_some() {
            rec.labelled = relabel;
            if relabel {
                self.have_labels = front.is_ok();
            } else {
                self.counters.labels_reused += 1;
            }
        }
        let stereo = match front {
            Ok(s) => s,
            Err(_) => {
                reject(&mut rec, Detection::FrontEnd, self.loc);
                return rec;
            }
        };
        rec.features = stereo.left;
        rec.stereo_matched = stereo.matched;
        self.high.features = self.high.features.max(stereo.left);
        if let Some(d) = self.monitor.check_front_end(stereo.left, stereo.matched) {
            reject(&mut rec, d, self.loc);
            return rec;
        }
        let r = self.loc.track();
        rec.tracked = true;
        rec.state = r.state;
        rec.inliers = r.inliers;
        rec.t_wc = pose_row(&r.t_wc);
        if r.lost {
            rec.detections |= Detection::TrackingLost.bit();
            self.counters.lost += 1;
        }
        rec.good = r.state == TrackState::Tracking
            && !r.lost
            && (!r.initialised || r.frame_index == 0)
            && (r.inliers >= self.monitor.params().good_inliers || r.frame_index == 0);
        self.high.landmarks = self.high.landmarks.max(r.landmarks);
        self.high.keyframes = self.high.keyframes.max(r.keyframes);
        rec
    }
}
