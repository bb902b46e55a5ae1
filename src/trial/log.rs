//! The trial log: every stream and event of one trial, written into its run folder.
//!
//! [`TrialLog::create`] opens the files; the runtime then feeds it:
//! - at the camera rate (30 Hz): [`TrialLog::cues`], [`TrialLog::assessment`],
//!   [`TrialLog::adaptation`];
//! - at the control rate (500 Hz): [`TrialLog::robot_state`], [`TrialLog::command`],
//!   [`TrialLog::cycle`], [`TrialLog::human_distance`], and [`TrialLog::event`] from anywhere;
//!
//! and [`TrialLog::finish`] closes it and writes the summary and the report.
//!
//! # Files (see ARCHITECTURE.md, "Files a trial leaves")
//! - `trial.mcap`: every stream on its own channel with a JSON schema (`log_mcap.rs` lists the
//!   topics and schemas), zstd-compressed chunks. A chunk is closed and flushed to the file every
//!   [`LogOptions::chunk_period_s`] of trial time, so a process killed with SIGKILL leaves a file
//!   the `mcap` reader reads (with `IgnoreEndMagic`) up to its last complete chunk.
//! - `indicators.csv`: the `hrc-adapt assess` table (`report::table`), one row per assessment.
//! - `robot.csv`: ur_rtde-style trace (`robot_io::trace::TraceWriter`, [`STATE_FIELD_NAMES`]),
//!   readable back by `robot_io::trace::Trace::read` and so by `ReplayRobot`.
//! - `summary.json`: `log_summary.rs`; its `motion` object comes from `motion_metrics.rs`,
//!   fed with every raw control-rate record (before any decimation or debouncing).
//! - `report.html` and its PNG plots: `report.rs`.
//!
//! Robot state goes to `/robot/state` and `robot.csv` decimated to 100 Hz (one sample per
//! 10 ms of trial time; [`LogOptions::robot_full_rate`] keeps every sample). Separation
//! samples are decimated the same way. Commands and events are all kept.
//!
//! # Safety events
//! The supervisor judges every 500 Hz command; around the handover (present, release,
//! retreat) its verdict flickers between SAF-REQ-007 stops and SAF-REQ-004 reductions from one
//! cycle to the next (about 1,900 transitions in an L2 trial). The runtime therefore logs a
//! `Safety` event (`/safety/events`, `summary.json`'s `safety_events`) only when the
//! (reaction, requirement) pair changes to a non-`passed` pair **and** the new pair has held
//! for 50 ms (`SAFETY_DEBOUNCE_S` in `runtime.rs`); the event is stamped with the time the pair
//! started, so `/safety/events` may lag the other channels by up to 50 ms. A return to
//! `passed` that holds 50 ms re-arms it. Nothing is lost: every individual verdict, with its
//! requirement and limits, is on `/robot/command` at the full control rate.
//!
//! # Threads and the control path
//! The control-rate methods only copy a `Copy` record into a ring preallocated at
//! [`TrialLog::create`] ([`LogOptions::ring_capacity`] records) and update the streaming
//! motion metrics (`motion_metrics.rs`: O(1) per record, buffers preallocated): no allocation,
//! no formatting, no I/O. The ring is drained (formatted, compressed, written) by the next
//! camera-rate call, and by [`TrialLog::finish`]; should it fill before, the control-rate call
//! drains it itself (counted in [`TrialFiles::synchronous_drains`]). That is the lockstep path
//! (`--robot sim`, one thread).
//!
//! In real time the control cycle runs on its own thread and logs through a [`ControlLog`]
//! instead: the same records into a wait-free single-producer ring, never blocking; the thread
//! that owns the trial log calls [`TrialLog::absorb`], which feeds each record through the same
//! path as the control-rate methods (metrics, decimation, ring). A full [`ControlLog`] drops and
//! counts ([`TrialFiles::dropped_records`]); the runtime turns any loss into an `error` ending.

#[path = "log_mcap.rs"]
pub(crate) mod mcap_out;
#[path = "motion_metrics.rs"]
pub(crate) mod motion;
#[path = "log_summary.rs"]
pub(crate) mod summary;
#[cfg(test)]
#[path = "log_tests.rs"]
mod tests;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::Error;
use robot_io::trace::{STATE_FIELD_NAMES, TraceWriter, WriteOptions, state_to_row};
use robot_io::{JointCommand, RobotState};
use safety::Verdict;
use serde::Serialize;

use super::events::TrialEvent;
use super::report;
use super::report::assess_report::table::IndicatorTable;
use mcap_out::ch;
pub(crate) use motion::CycleRecord;
use motion::MotionMetrics;
use summary::FrameRecord;

/// The MCAP file, inside the run folder.
pub(crate) const MCAP_FILE: &str = "trial.mcap";
/// The indicator table.
pub(crate) const INDICATORS_FILE: &str = "indicators.csv";
/// The robot trace.
pub(crate) const ROBOT_FILE: &str = "robot.csv";
/// The summary.
pub(crate) const SUMMARY_FILE: &str = "summary.json";

/// Who, what and how: written into `summary.json`, `/trial/meta` and the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct TrialMeta {
    /// Participant id.
    pub(crate) participant: String,
    /// Task condition (`L1`, `L2`, `L3`).
    pub(crate) condition: String,
    /// Policy name (`fixed`, `adaptive`).
    pub(crate) policy: String,
    /// Seed of the simulation (and of anything random in the trial).
    pub(crate) seed: u64,
    /// The operator is simulated: the data is not from a person.
    pub(crate) simulated: bool,
    /// Where the operator cues came from when not from the simulated operator:
    /// `recorded:<file name>` (`hrc-adapt trial --cues`). Absent (not written) for the
    /// simulated operator.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) cue_source: Option<String>,
    /// Wall-clock start, ISO 8601 UTC (`2026-01-01T12:00:00Z`).
    pub(crate) started_utc: String,
    /// The robot backend (`sim`, `emulator`, or the UR5e's address).
    pub(crate) robot: String,
}

/// How the log records.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LogOptions {
    /// Keep every robot state sample instead of decimating to 100 Hz.
    pub(crate) robot_full_rate: bool,
    /// Close (and flush) an MCAP chunk at least this often, in trial time [s] (> 0). Bounds what
    /// a killed process loses.
    pub(crate) chunk_period_s: f64,
    /// Control-rate records held between drains (≥ 1).
    pub(crate) ring_capacity: usize,
    /// HRC-CWL where the category becomes medium [-] (for the report's bands).
    pub(crate) cwl_medium_from: f64,
    /// HRC-CWL where the category becomes high [-].
    pub(crate) cwl_high_from: f64,
    /// The assessor's sliding window [s] (for the report's legends).
    pub(crate) window_horizon_s: f64,
    /// Render `report.html` and its plots in [`TrialLog::finish`].
    pub(crate) write_report: bool,
}

impl Default for LogOptions {
    /// 100 Hz robot state, 1 s chunks, 4096 records of ring (8 s at 500 Hz), the assessor's
    /// default category thresholds and window, with the report.
    fn default() -> Self {
        let cfg = assess::AssessConfig::default();
        Self {
            robot_full_rate: false,
            chunk_period_s: 1.0,
            ring_capacity: 4096,
            cwl_medium_from: cfg.composite.medium_from,
            cwl_high_from: cfg.composite.high_from,
            window_horizon_s: cfg.window.horizon_s,
            write_report: true,
        }
    }
}

/// The files a finished log left, and what went into them.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TrialFiles {
    /// The run folder.
    pub(crate) dir: PathBuf,
    /// `trial.mcap`.
    pub(crate) mcap: PathBuf,
    /// `indicators.csv`.
    pub(crate) indicators_csv: PathBuf,
    /// `robot.csv`.
    pub(crate) robot_csv: PathBuf,
    /// `summary.json`.
    pub(crate) summary_json: PathBuf,
    /// `report.html` (when [`LogOptions::write_report`]).
    pub(crate) report_html: Option<PathBuf>,
    /// The report's PNG plots.
    pub(crate) plots: Vec<PathBuf>,
    /// Messages written per MCAP topic.
    pub(crate) message_counts: BTreeMap<String, u64>,
    /// Times a control-rate call found the ring full and drained it itself.
    pub(crate) synchronous_drains: u64,
    /// Control-rate records lost because a [`ControlLog`]'s ring was full (0 in a sound run).
    pub(crate) dropped_records: u64,
}

/// A control-rate record, copied into the ring as is.
// Records are `Copy` and of one size in a ring preallocated once; boxing the robot state would
// allocate on every control-rate call.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy)]
enum HotRecord {
    State(f64, RobotState),
    Command(f64, JointCommand, Verdict),
    Distance(f64, Option<f64>),
    Event(f64, TrialEvent),
    /// The cycle record and the cycle's executed jerk, max over the joints of |j| [rad/s³].
    Cycle(f64, CycleRecord, Option<f64>),
}

/// Where the control cycle logs: the trial log itself (one thread: the mock clock) or a
/// [`ControlLog`] (the control thread's end of a wait-free ring; real time). Every method
/// copies a `Copy` record; none allocates or does I/O.
pub(crate) trait ControlSink {
    /// See [`TrialLog::robot_state`].
    fn robot_state(&mut self, t_s: f64, state: &RobotState) -> crate::Result<()>;
    /// See [`TrialLog::command`].
    fn command(&mut self, t_s: f64, cmd: &JointCommand, verdict: &Verdict) -> crate::Result<()>;
    /// See [`TrialLog::cycle`].
    fn cycle(&mut self, t_s: f64, rec: &CycleRecord) -> crate::Result<()>;
    /// See [`TrialLog::human_distance`].
    fn human_distance(&mut self, t_s: f64, min_distance_m: Option<f64>) -> crate::Result<()>;
    /// See [`TrialLog::event`].
    fn event(&mut self, t_s: f64, event: &TrialEvent) -> crate::Result<()>;
}

impl ControlSink for TrialLog {
    fn robot_state(&mut self, t_s: f64, state: &RobotState) -> crate::Result<()> {
        TrialLog::robot_state(self, t_s, state)
    }
    fn command(&mut self, t_s: f64, cmd: &JointCommand, verdict: &Verdict) -> crate::Result<()> {
        TrialLog::command(self, t_s, cmd, verdict)
    }
    fn cycle(&mut self, t_s: f64, rec: &CycleRecord) -> crate::Result<()> {
        TrialLog::cycle(self, t_s, rec)
    }
    fn human_distance(&mut self, t_s: f64, min_distance_m: Option<f64>) -> crate::Result<()> {
        TrialLog::human_distance(self, t_s, min_distance_m)
    }
    fn event(&mut self, t_s: f64, event: &TrialEvent) -> crate::Result<()> {
        TrialLog::event(self, t_s, event)
    }
}

/// The control thread's end of the log: a wait-free single-producer ring of control-rate
/// records, preallocated, read by [`TrialLog::absorb`] on the thread that owns the trial log.
/// A push never blocks and never allocates; when the ring is full the record is dropped and
/// counted (`summary.json`: `log.dropped_records`, which a trial's tests require to be 0).
pub(crate) struct ControlLog {
    producer: rtrb::Producer<HotRecord>,
    dropped: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

/// The reading end of a [`ControlLog`].
pub(crate) struct ControlLogReader {
    consumer: rtrb::Consumer<HotRecord>,
    dropped: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl ControlLog {
    /// A ring of `capacity` records [-] (a few seconds of the control rate: 4 records a cycle).
    pub(crate) fn new(capacity: usize) -> (ControlLog, ControlLogReader) {
        let (producer, consumer) = rtrb::RingBuffer::new(capacity.max(1));
        let dropped = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
        (
            ControlLog {
                producer,
                dropped: dropped.clone(),
            },
            ControlLogReader { consumer, dropped },
        )
    }

    /// Records the ring has room for now [-] (tests).
    #[cfg(test)]
    pub(crate) fn free_slots(&self) -> usize {
        self.producer.slots()
    }

    fn push(&mut self, rec: HotRecord) -> crate::Result<()> {
        if self.producer.push(rec).is_err() {
            self.dropped
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        Ok(())
    }
}

impl ControlSink for ControlLog {
    fn robot_state(&mut self, t_s: f64, state: &RobotState) -> crate::Result<()> {
        self.push(HotRecord::State(t_s, *state))
    }
    fn command(&mut self, t_s: f64, cmd: &JointCommand, verdict: &Verdict) -> crate::Result<()> {
        self.push(HotRecord::Command(t_s, *cmd, *verdict))
    }
    fn cycle(&mut self, t_s: f64, rec: &CycleRecord) -> crate::Result<()> {
        self.push(HotRecord::Cycle(t_s, *rec, None))
    }
    fn human_distance(&mut self, t_s: f64, min_distance_m: Option<f64>) -> crate::Result<()> {
        self.push(HotRecord::Distance(t_s, min_distance_m))
    }
    fn event(&mut self, t_s: f64, event: &TrialEvent) -> crate::Result<()> {
        self.push(HotRecord::Event(t_s, *event))
    }
}

/// What the report plots of one adaptation [-] and [s].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct AdaptationRecord {
    /// Time [s].
    pub(crate) t_s: f64,
    /// Speed scale [-].
    pub(crate) speed_scale: f64,
    /// Acceleration scale [-].
    pub(crate) acceleration_scale: f64,
    /// Jerk scale [-].
    pub(crate) jerk_scale: f64,
    /// Start delay [s].
    pub(crate) start_delay_s: f64,
    /// Minimum approach duration [s].
    pub(crate) min_approach_duration_s: f64,
    /// The active rule's indicator (`none`).
    pub(crate) indicator: &'static str,
}

/// What the report plots of one assessment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct IndicatorRecord {
    /// The plot sample the `assess` figure uses.
    pub(crate) sample: report::assess_report::Sample,
    /// Windowed normalised components AED, TID, ICD, ASD̃, OHD [-].
    pub(crate) windowed: [f64; 5],
    /// The reported dominant indicator.
    pub(crate) dominant: Option<assess::Indicator>,
}

/// What the report plots of the control cycles, one sample per 10 ms of trial time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct CycleSample {
    /// Time [s].
    pub(crate) t_s: f64,
    /// The planner's time scale [-].
    pub(crate) time_scale: f64,
    /// The planner's jerk limit [rad/s³].
    pub(crate) jerk_limit_rad_s3: f64,
    /// The largest executed |jerk| over the joints since the previous sample [rad/s³] (NaN
    /// when none was measured).
    pub(crate) jerk_abs_max_rad_s3: f64,
}

/// Everything kept in memory for the summary and the report (camera-rate and decimated data).
#[derive(Debug, Default)]
pub(crate) struct Recorded {
    /// Per assessment, for the summary.
    pub(crate) frames: Vec<FrameRecord>,
    /// Per assessment, for the plots.
    pub(crate) indicators: Vec<IndicatorRecord>,
    /// Per adaptation.
    pub(crate) adaptations: Vec<AdaptationRecord>,
    /// (t [s], TCP speed [m/s]) per logged robot state.
    pub(crate) tcp_speed: Vec<(f64, f64)>,
    /// (t [s], minimum human distance [m]) per logged separation sample.
    pub(crate) distance: Vec<(f64, Option<f64>)>,
    /// Every event.
    pub(crate) events: Vec<(f64, TrialEvent)>,
    /// Per 10 ms of cycle records.
    pub(crate) cycles: Vec<CycleSample>,
}

/// Decimates a sampled stream to one sample per period.
#[derive(Debug, Clone, Copy)]
struct Decimator {
    period_s: f64,
    last: Option<f64>,
}

impl Decimator {
    fn new(period_s: f64) -> Self {
        Self {
            period_s,
            last: None,
        }
    }

    /// Keep the sample at `t_s`? (A relative tolerance absorbs clock rounding.)
    fn keep(&mut self, t_s: f64) -> bool {
        let keep = self
            .last
            .is_none_or(|l| t_s - l >= self.period_s * (1.0 - 1e-6));
        if keep {
            self.last = Some(t_s);
        }
        keep
    }
}

/// 100 Hz.
const DECIMATED_PERIOD_S: f64 = 0.01;

/// The log of one trial. See the module docs.
pub(crate) struct TrialLog {
    dir: PathBuf,
    meta: TrialMeta,
    options: LogOptions,
    mcap: mcap::Writer<BufWriter<File>>,
    channels: [u16; mcap_out::CHANNELS.len()],
    sequences: [u32; mcap_out::CHANNELS.len()],
    indicators: IndicatorTable<BufWriter<File>>,
    robot: TraceWriter<BufWriter<File>>,
    ring: Vec<HotRecord>,
    state_decimator: Decimator,
    distance_decimator: Decimator,
    cycle_decimator: Decimator,
    /// Largest executed |jerk| since the last [`CycleSample`] (drain side) [rad/s³].
    cycle_jerk_envelope: f64,
    motion: MotionMetrics,
    buf: Vec<u8>,
    row: [f64; 44],
    next_chunk_t: f64,
    recorded: Recorded,
    synchronous_drains: u64,
    /// Control-rate records a [`ControlLog`] could not queue (its ring was full).
    dropped_records: u64,
}

impl std::fmt::Debug for TrialLog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrialLog")
            .field("dir", &self.dir)
            .field("meta", &self.meta)
            .field("options", &self.options)
            .field("ring_len", &self.ring.len())
            .field("sequences", &self.sequences)
            .finish_non_exhaustive()
    }
}

fn ns(t_s: f64) -> u64 {
    if t_s.is_finite() && t_s > 0.0 {
        (t_s * 1e9).round() as u64
    } else {
        0
    }
}

impl TrialLog {
    /// Creates `dir` (if needed) and its log files, and writes the channel schemas and the
    /// trial's identity.
    pub(crate) fn create(dir: &Path, meta: &TrialMeta, options: LogOptions) -> crate::Result<Self> {
        ensure!(
            options.chunk_period_s > 0.0 && options.ring_capacity > 0,
            Error::config(
                "log options",
                "need chunk_period_s > 0 and ring_capacity ≥ 1"
            )
        );
        std::fs::create_dir_all(dir).map_err(Error::io("create the run folder", dir))?;
        // A run folder is never reused (issue 10): another trial's log in it is refused, and
        // the files are created exclusively, so two trials cannot share one.
        for name in [SUMMARY_FILE, super::report::HTML_FILE] {
            ensure!(
                !dir.join(name).exists(),
                Error::data(
                    dir.display(),
                    format!("holds another trial's log ({name}); refusing to overwrite it")
                )
            );
        }
        let open = |name: &str| {
            let p = dir.join(name);
            File::create_new(&p)
                .map(BufWriter::new)
                .map_err(Error::io("create (another trial's log?)", &p))
        };
        let write_options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library("hrc-adapt")
            // Compress on the thread that closes the chunk (the log writer or the cue cycle,
            // both at background priority), not on zstd's worker threads: mcap starts one per
            // physical CPU at normal priority, and each chunk's compression then took every
            // core from the control thread and the emulator's clock (issue 10: 96 of the 118
            // gaps of ≥ 8 ms in the loop's samples of one emulator run began within 50 ms after
            // a chunk closed).
            .compression_threads(0)
            // Chunks close on `chunk_period_s` of trial time, or at 4 MiB, whichever is first.
            .chunk_size(Some(4 << 20));
        let mut mcap = write_options
            .create(open(MCAP_FILE)?)
            .map_err(Error::mcap("start", &dir.join(MCAP_FILE)))?;
        let mut channels = [0u16; mcap_out::CHANNELS.len()];
        for (id, c) in channels.iter_mut().zip(mcap_out::CHANNELS) {
            let schema = mcap
                .add_schema(c.schema_name, "jsonschema", c.schema.as_bytes())
                .map_err(Error::mcap("write the schemas into", &dir.join(MCAP_FILE)))?;
            *id = mcap
                .add_channel(schema, c.topic, "json", &BTreeMap::new())
                .map_err(Error::mcap("write the channels into", &dir.join(MCAP_FILE)))?;
        }
        let indicators = IndicatorTable::new(open(INDICATORS_FILE)?)
            .map_err(Error::csv("start", &dir.join(INDICATORS_FILE)))?;
        let robot = TraceWriter::new(
            open(ROBOT_FILE)?,
            &STATE_FIELD_NAMES,
            &WriteOptions::ur_rtde(),
        )
        .map_err(|e| {
            Error::from(e).context(format!("cannot start {}", dir.join(ROBOT_FILE).display()))
        })?;
        let mut log = Self {
            dir: dir.to_path_buf(),
            meta: meta.clone(),
            ring: Vec::with_capacity(options.ring_capacity),
            options,
            mcap,
            channels,
            sequences: [0; mcap_out::CHANNELS.len()],
            indicators,
            robot,
            state_decimator: Decimator::new(DECIMATED_PERIOD_S),
            distance_decimator: Decimator::new(DECIMATED_PERIOD_S),
            cycle_decimator: Decimator::new(DECIMATED_PERIOD_S),
            cycle_jerk_envelope: f64::NAN,
            motion: MotionMetrics::new(),
            buf: Vec::with_capacity(4096),
            row: [0.0; 44],
            next_chunk_t: 0.0,
            recorded: Recorded::default(),
            synchronous_drains: 0,
            dropped_records: 0,
        };
        let meta_json =
            serde_json::to_vec(meta).map_err(Error::json("write", "the trial's identity"))?;
        log.write(ch::META, 0.0, &meta_json)?;
        // The schemas and the identity reach the file at once.
        log.mcap
            .flush()
            .map_err(Error::mcap("flush", &log.dir.join(MCAP_FILE)))?;
        log.next_chunk_t = log.options.chunk_period_s;
        Ok(log)
    }

    /// Writes one message on channel `c` at trial time `t_s` [s].
    fn write(&mut self, c: usize, t_s: f64, data: &[u8]) -> crate::Result<()> {
        let (Some(&channel_id), Some(seq)) = (self.channels.get(c), self.sequences.get_mut(c))
        else {
            return Err(Error::data(MCAP_FILE, format!("no channel {c}")));
        };
        *seq = seq.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: *seq,
            log_time: ns(t_s),
            publish_time: ns(t_s),
        };
        self.mcap
            .write_to_known_channel(&header, data)
            .map_err(Error::mcap("write", &self.dir.join(MCAP_FILE)))?;
        Ok(())
    }

    /// Writes a `serde_json` value on channel `c`.
    fn write_value(&mut self, c: usize, t_s: f64, v: &serde_json::Value) -> crate::Result<()> {
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        let res = serde_json::to_writer(&mut buf, v)
            .map_err(Error::json("write", "a log message"))
            .and_then(|()| self.write(c, t_s, &buf));
        self.buf = buf;
        res
    }

    /// Closes the current chunk and flushes every file once `t_s` passes the chunk period.
    fn maybe_close_chunk(&mut self, t_s: f64) -> crate::Result<()> {
        if t_s >= self.next_chunk_t {
            self.mcap
                .flush()
                .map_err(Error::mcap("flush", &self.dir.join(MCAP_FILE)))?;
            self.robot.flush()?;
            while self.next_chunk_t <= t_s {
                self.next_chunk_t += self.options.chunk_period_s;
            }
        }
        Ok(())
    }

    /// Formats and writes every record in the ring.
    fn drain(&mut self) -> crate::Result<()> {
        let ring = std::mem::take(&mut self.ring);
        let mut res = Ok(());
        for rec in &ring {
            res = self.write_hot(rec);
            if res.is_err() {
                break;
            }
        }
        self.ring = ring;
        self.ring.clear();
        res
    }

    fn write_hot(&mut self, rec: &HotRecord) -> crate::Result<()> {
        let mut buf = std::mem::take(&mut self.buf);
        let res = (|| -> crate::Result<()> {
            match *rec {
                HotRecord::State(t, ref s) => {
                    mcap_out::robot_state_json(&mut buf, t, s);
                    self.write(ch::ROBOT_STATE, t, &buf)?;
                    state_to_row(s, &mut self.row);
                    self.robot.write_row(&self.row)?;
                    self.recorded
                        .tcp_speed
                        .push((t, mcap_out::tcp_speed_m_s(s)));
                    self.maybe_close_chunk(t)?;
                }
                HotRecord::Command(t, ref c, ref v) => {
                    mcap_out::command_json(&mut buf, t, c, v);
                    self.write(ch::COMMAND, t, &buf)?;
                    self.maybe_close_chunk(t)?;
                }
                HotRecord::Distance(t, d) => {
                    mcap_out::separation_json(&mut buf, t, d);
                    self.write(ch::SEPARATION, t, &buf)?;
                    self.recorded.distance.push((t, d));
                }
                HotRecord::Event(t, ref e) => {
                    let c = mcap_out::event_json(&mut buf, t, e);
                    self.write(c, t, &buf)?;
                    self.recorded.events.push((t, *e));
                }
                HotRecord::Cycle(t, ref r, jerk) => {
                    mcap_out::cycle_json(&mut buf, t, r, jerk);
                    self.write(ch::CYCLE, t, &buf)?;
                    if let Some(j) = jerk {
                        self.cycle_jerk_envelope = self.cycle_jerk_envelope.max(j);
                    }
                    if self.cycle_decimator.keep(t) {
                        self.recorded.cycles.push(CycleSample {
                            t_s: t,
                            time_scale: r.time_scale,
                            jerk_limit_rad_s3: r.jerk_limit_rad_s3,
                            jerk_abs_max_rad_s3: self.cycle_jerk_envelope,
                        });
                        self.cycle_jerk_envelope = f64::NAN;
                    }
                    self.maybe_close_chunk(t)?;
                }
            }
            Ok(())
        })();
        self.buf = buf;
        res
    }

    /// Queues a control-rate record; drains first if the ring is full.
    fn push(&mut self, rec: HotRecord) -> crate::Result<()> {
        if self.ring.len() == self.ring.capacity() {
            self.synchronous_drains += 1;
            self.drain()?;
        }
        self.ring.push(rec);
        Ok(())
    }

    /// Logs the cue frame given to the assessor at trial time `t_s` [s] (camera rate).
    pub(crate) fn cues(&mut self, t_s: f64, frame: &assess::CueFrame) -> crate::Result<()> {
        self.drain()?;
        self.write_value(ch::CUES, t_s, &mcap_out::cues_value(t_s, frame))?;
        self.maybe_close_chunk(t_s)
    }

    /// Logs an assessment (camera rate): `/assessment`, a row of `indicators.csv`, and what the
    /// summary and the report need.
    pub(crate) fn assessment(
        &mut self,
        t_s: f64,
        a: &assess::Assessment,
        ws: &assess::Workspace,
    ) -> crate::Result<()> {
        self.drain()?;
        self.write_value(ch::ASSESSMENT, t_s, &mcap_out::assessment_value(t_s, a, ws))?;
        self.indicators
            .write(ws, a)
            .map_err(Error::csv("write", &self.dir.join(INDICATORS_FILE)))?;
        self.recorded.frames.push(FrameRecord::of(a));
        let w = &a.windowed;
        self.recorded.indicators.push(IndicatorRecord {
            sample: report::assess_report::Sample::of(a),
            windowed: [w.aed, w.tid, w.icd, w.asd_norm, w.ohd],
            dominant: a.dominant.indicator,
        });
        self.maybe_close_chunk(t_s)
    }

    /// Logs the policy's adaptation (camera rate).
    pub(crate) fn adaptation(&mut self, t_s: f64, a: &policies::Adaptation) -> crate::Result<()> {
        self.drain()?;
        let value =
            mcap_out::adaptation_value(t_s, a).map_err(Error::json("write", "the adaptation"))?;
        self.write_value(ch::ADAPTATION, t_s, &value)?;
        self.recorded.adaptations.push(AdaptationRecord {
            t_s,
            speed_scale: a.speed_scale.get(),
            acceleration_scale: a.acceleration_scale.get(),
            jerk_scale: a.jerk_scale.get(),
            start_delay_s: a.timing.start_delay_s,
            min_approach_duration_s: a.timing.min_approach_duration_s,
            indicator: policies::indicator_key(a.reason.indicator),
        });
        self.maybe_close_chunk(t_s)
    }

    /// Takes one control-rate record: the motion metrics see every record, in order; the
    /// state and distance streams are decimated; the record is copied into the ring. No
    /// allocation, no I/O (unless the ring is full). The control-rate methods below and
    /// [`TrialLog::absorb`] (records from a [`ControlLog`]) both come here, so a record has the
    /// same effect whichever way it arrives.
    fn ingest(&mut self, rec: HotRecord) -> crate::Result<()> {
        match rec {
            HotRecord::State(t_s, ref state) => {
                self.motion.on_state(t_s, state);
                if self.options.robot_full_rate || self.state_decimator.keep(t_s) {
                    self.push(rec)?;
                }
                Ok(())
            }
            HotRecord::Command(t_s, _, ref verdict) => {
                self.motion.on_verdict(t_s, verdict);
                self.push(rec)
            }
            HotRecord::Cycle(t_s, ref cycle, _) => {
                self.motion.on_cycle(t_s, cycle);
                let jerk = self.motion.jerk_abs_max(t_s);
                self.push(HotRecord::Cycle(t_s, *cycle, jerk))
            }
            HotRecord::Distance(t_s, d) => {
                self.motion.on_distance(t_s, d);
                if self.options.robot_full_rate || self.distance_decimator.keep(t_s) {
                    self.push(rec)?;
                }
                Ok(())
            }
            HotRecord::Event(..) => self.push(rec),
        }
    }

    /// Takes every record a [`ControlLog`] queued so far (in order), as if its calls had been
    /// made here. The cue thread calls it before each of its own log calls and at the end.
    pub(crate) fn absorb(&mut self, from: &mut ControlLogReader) -> crate::Result<()> {
        self.dropped_records += from.dropped.swap(0, std::sync::atomic::Ordering::Relaxed);
        while let Ok(rec) = from.consumer.pop() {
            self.ingest(rec)?;
        }
        Ok(())
    }

    /// Logs a robot state (control rate; decimated to 100 Hz unless
    /// [`LogOptions::robot_full_rate`]; every state goes to the motion metrics). Copies into
    /// the ring: no allocation, no I/O (unless the ring is full).
    pub(crate) fn robot_state(&mut self, t_s: f64, state: &RobotState) -> crate::Result<()> {
        self.ingest(HotRecord::State(t_s, *state))
    }

    /// Logs the command the controller asked for and the supervisor's verdict on it (control
    /// rate; every command). Copies into the ring.
    pub(crate) fn command(
        &mut self,
        t_s: f64,
        cmd: &JointCommand,
        verdict: &Verdict,
    ) -> crate::Result<()> {
        self.ingest(HotRecord::Command(t_s, *cmd, *verdict))
    }

    /// Logs what the control cycle at `t_s` [s] reports about itself (control rate; every
    /// cycle, `/robot/cycle`, after [`TrialLog::robot_state`] of the same cycle so the record
    /// carries its executed jerk). Copies into the ring.
    pub(crate) fn cycle(&mut self, t_s: f64, rec: &CycleRecord) -> crate::Result<()> {
        self.ingest(HotRecord::Cycle(t_s, *rec, None))
    }

    /// Logs the minimum distance between a tracked human point and the arm [m] (`None` when no
    /// human point is tracked); decimated like the robot state. Copies into the ring.
    pub(crate) fn human_distance(
        &mut self,
        t_s: f64,
        min_distance_m: Option<f64>,
    ) -> crate::Result<()> {
        self.ingest(HotRecord::Distance(t_s, min_distance_m))
    }

    /// Logs a trial event (any rate; copies into the ring). `Safety` events go to
    /// `/safety/events`, the others to `/task/events`.
    pub(crate) fn event(&mut self, t_s: f64, event: &TrialEvent) -> crate::Result<()> {
        self.ingest(HotRecord::Event(t_s, *event))
    }

    /// Writes out what the control-rate calls queued in the ring (what every camera-rate call
    /// does first).
    #[cfg(test)]
    pub(crate) fn drain_ring(&mut self) -> crate::Result<()> {
        self.drain()
    }

    /// The robot side's servo statistics at the end of the trial (the in-process emulator's):
    /// `summary.json`'s `motion.robot_servo`.
    pub(crate) fn set_robot_servo(&mut self, stats: robot_io::emulator::ServoStats) {
        self.motion.set_robot_servo(stats);
    }

    /// `summary.json`'s `motion.scheduling`.
    pub(crate) fn set_scheduling(&mut self, s: crate::trial::priority::SchedulingSummary) {
        self.motion.set_scheduling(s);
    }

    /// `summary.json`'s `motion.emulator_clock`.
    pub(crate) fn set_emulator_clock(&mut self, stats: robot_io::emulator::ClockStats) {
        self.motion.set_emulator_clock(stats);
    }

    /// Drains the ring, closes every file, writes `summary.json` and the report.
    pub(crate) fn finish(mut self) -> crate::Result<TrialFiles> {
        self.drain()?;
        self.motion.finish();
        let mcap_summary = self
            .mcap
            .finish()
            .map_err(Error::mcap("finish", &self.dir.join(MCAP_FILE)))?;
        let mut message_counts = BTreeMap::new();
        if let Some(stats) = &mcap_summary.stats {
            for (id, n) in &stats.channel_message_counts {
                if let Some(c) = mcap_summary.channels.get(id) {
                    message_counts.insert(c.topic.clone(), *n);
                }
            }
        }
        let TrialLog {
            dir,
            meta,
            options,
            mcap,
            indicators,
            mut robot,
            recorded,
            synchronous_drains,
            dropped_records,
            motion,
            ..
        } = self;
        use std::io::Write;
        mcap.into_inner()
            .flush()
            .map_err(Error::io("flush", &dir.join(MCAP_FILE)))?;
        let indicators_csv = dir.join(INDICATORS_FILE);
        indicators
            .finish()
            .map_err(Error::io("finish", &indicators_csv))?
            .flush()
            .map_err(Error::io("flush", &indicators_csv))?;
        robot.flush()?;
        robot
            .into_inner()
            .flush()
            .map_err(Error::io("flush", &dir.join(ROBOT_FILE)))?;

        let summary = summary::compute(&meta, &recorded.frames, &recorded.events, &motion);
        let summary_json = dir.join(SUMMARY_FILE);
        let json = summary::to_json(&summary).map_err(Error::json("write", SUMMARY_FILE))?;
        std::fs::write(&summary_json, json).map_err(Error::io("write", &summary_json))?;

        let (report_html, plots) = if options.write_report {
            let r = report::write(&dir, &meta, &options, &recorded, &summary)?;
            (Some(r.html), r.plots)
        } else {
            (None, Vec::new())
        };
        Ok(TrialFiles {
            mcap: dir.join(MCAP_FILE),
            indicators_csv: dir.join(INDICATORS_FILE),
            robot_csv: dir.join(ROBOT_FILE),
            summary_json,
            report_html,
            plots,
            message_counts,
            synchronous_drains,
            dropped_records,
            dir,
        })
    }
}

/// (Tests; external readers use the `mcap` crate the same way.)
#[cfg(test)]
/// Reads every message of an MCAP file that a reader can reach: the whole file if it is
/// complete, else everything up to the last complete chunk (a damaged tail is ignored).
/// Returns (topic, log time [ns], JSON text) per message, and whether the tail was damaged.
pub(crate) fn read_mcap_messages(bytes: &[u8]) -> crate::Result<(Vec<ReadMessage>, bool)> {
    use std::borrow::Cow;
    let stream =
        mcap::MessageStream::new_with_options(bytes, mcap::read::Options::IgnoreEndMagic.into())
            .map_err(Error::mcap("read", Path::new("the mcap bytes")))?;
    let mut out = Vec::new();
    for m in stream {
        match m {
            Ok(m) => out.push(ReadMessage {
                topic: m.channel.topic.clone(),
                schema: m.channel.schema.as_ref().map(|s| {
                    (
                        s.name.clone(),
                        s.encoding.clone(),
                        String::from_utf8_lossy(&s.data).into_owned(),
                    )
                }),
                message_encoding: m.channel.message_encoding.clone(),
                log_time_ns: m.log_time,
                data: match m.data {
                    Cow::Borrowed(b) => b.to_vec(),
                    Cow::Owned(v) => v,
                },
            }),
            Err(_) => return Ok((out, true)),
        }
    }
    Ok((out, false))
}

/// One message read back by [`read_mcap_messages`].
#[cfg(test)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ReadMessage {
    /// The channel's topic.
    pub(crate) topic: String,
    /// The channel's schema: (name, encoding, text).
    pub(crate) schema: Option<(String, String, String)>,
    /// The channel's message encoding.
    pub(crate) message_encoding: String,
    /// Log time [ns].
    pub(crate) log_time_ns: u64,
    /// The message bytes.
    pub(crate) data: Vec<u8>,
}
