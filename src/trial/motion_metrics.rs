//! Motion quality: what the arm really did, measured from the **raw** per-cycle signals the log
//! receives (every 500 Hz robot state, every supervisor verdict, every cycle record, every
//! separation sample), never from the decimated or debounced streams. The definitions are
//! restated in README.md, "Motion quality metrics"; the constants are below.
//!
//! # Cycles
//! The records of one control cycle share its trial time t ([`MotionMetrics::on_state`],
//! [`MotionMetrics::on_verdict`], [`MotionMetrics::on_cycle`], [`MotionMetrics::on_distance`],
//! in any order). A cycle is evaluated when a record of another time arrives or at
//! [`MotionMetrics::finish`]: its verdict first (stop windows), then its state.
//!
//! # Stop windows
//! A stop window starts at the first cycle whose verdict is `Stopped` or `Halted` and ends
//! [`STOP_TAIL_S`] after the last such cycle of the run; a stop less than [`STOP_TAIL_S`] after
//! the previous one extends the same window. A cycle is *inside* when its time lies in a window
//! (closed interval); a window still open when the trial ends ends at the last cycle. A window
//! with a SAF-REQ-007 stop is a *separation* window (a real separation stop); its
//! requirements, first violation (its `Display`) and the minimum human distance over its
//! cycles are kept. "Outside stops" figures leave out every cycle inside any window.
//!
//! # Jerk
//! From the joint velocities q̇ of three successive states with controller timestamps
//! t₀ < t₁ < t₂ (the real Δt, 4–24 ms when the RTDE path skips samples):
//! j = ((q̇₂ − q̇₁)/(t₂ − t₁) − (q̇₁ − q̇₀)/(t₁ − t₀)) / ((t₂ − t₀)/2) [rad/s³],
//! exact for a quadratic q̇(t), attributed to the cycle of the newest state. A state whose
//! timestamp does not advance is a repeat and is skipped. RMS and max of |j| per joint and over
//! all joints; the overall RMS is √(Σ_joints Σ_samples j² / (6 n)).
//!
//! # Jerk limit
//! A jerk sample *exceeds* when max over the joints of |j| > [`JERK_LIMIT_FACTOR`] × the cycle's
//! [`CycleRecord::jerk_limit_rad_s3`] (the largest joint limit in force). Only samples whose
//! cycle has a record with a finite limit > 0 are judged.
//!
//! # Velocity reversals
//! Per joint: a sample with |q̇| > [`REVERSAL_MIN_SPEED_RAD_S`] whose sign is opposite to that of
//! the previous sample with |q̇| > [`REVERSAL_MIN_SPEED_RAD_S`], at most [`REVERSAL_WINDOW_S`]
//! earlier (trial time). Each sign change counts once, at the sample that completes it (which
//! decides inside / outside).
//!
//! # Stop-and-go
//! The TCP speed v = |(ẋ, ẏ, ż)| of every state, its recent peak P(t) = max v over
//! [t − [`PEAK_WINDOW_S`], t]. Armed, a sample with P ≥ [`MIN_PEAK_M_S`] and v < P/2 starts a
//! dip, with the peak P frozen. The dip is a **stop-and-go event** if v recovers — gets back to
//! ≥ [`RECOVERY_SHARE`] · P, "go" again — at most [`RECOVERY_S`] after the dip started; the
//! event is outside stops only if no sample of the dip is inside a stop window. A dip not
//! recovered by then is no event (the arm came to a stop, or went on slower: a speed that only
//! hovers about P/2, as a motion slowed smoothly for a nearby hand does, is not stop-and-go),
//! and the detector re-arms once v ≥ P/2 again.
//!
//! # Cycle records, latency and jitter
//! Missed cycles are summed from [`CycleRecord::missed`]. Latency and wake jitter go into
//! fixed log-spaced histograms ([`LogHistogram`]: [`BINS_PER_DECADE`] bins per decade from
//! 1 µs to 1 s, a bin's upper edge is 10^(1/40) ≈ 1.059× its lower edge): p50 and p99 are the
//! upper edge of the bin holding the nearest-rank sample (so at most 5.9 % above the exact
//! value), capped at the exact maximum; values under 1 µs (negative lateness included) fall in
//! an underflow bin reported as 1 µs, values over 1 s in an overflow bin reported as the
//! maximum. `None` values (mock clock) are not counted; with none at all the summary writes
//! `null`.
//!
//! # Allocation
//! Everything is preallocated in [`MotionMetrics::new`]: running sums and maxima, the
//! histograms, a bounded ring for the sliding peak, and lists of capacity
//! [`LIST_CAPACITY`] for the stop windows and the stop-and-go events (beyond it they are still
//! counted, no longer listed). The per-cycle calls allocate nothing.

use std::collections::{BTreeMap, VecDeque};

use robot_io::RobotState;
use robot_io::emulator::{ClockStats, SERVO_LATE_BINS, ServoStats};
use safety::{Requirement, Verdict, Violation};
use serde::Serialize;

use super::summary::r6;
use crate::trial::priority::SchedulingSummary;

/// A stop window ends this long after its last stop cycle [s].
pub(crate) const STOP_TAIL_S: f64 = 1.0;
/// Joint speed above which a sample takes part in a reversal [rad/s].
pub(crate) const REVERSAL_MIN_SPEED_RAD_S: f64 = 0.03;
/// The two sides of a reversal are at most this far apart [s].
pub(crate) const REVERSAL_WINDOW_S: f64 = 0.3;
/// The recent peak of the TCP speed is taken over this trailing window [s].
pub(crate) const PEAK_WINDOW_S: f64 = 1.0;
/// A dip is a stop-and-go event if the speed recovers within this time [s].
pub(crate) const RECOVERY_S: f64 = 0.5;
/// A dip has recovered when the speed is back at this share of the peak before it [-].
pub(crate) const RECOVERY_SHARE: f64 = 0.8;
/// A recent peak below this TCP speed starts no dip (the arm is at rest) [m/s].
pub(crate) const MIN_PEAK_M_S: f64 = 0.02;
/// Executed jerk is judged against this factor × the planner's jerk limit [-].
pub(crate) const JERK_LIMIT_FACTOR: f64 = 1.1;
/// Histogram bins per decade (1 µs to 1 s: six decades).
pub(crate) const BINS_PER_DECADE: usize = 40;
/// Stop windows and stop-and-go events listed (each list); more are counted only.
pub(crate) const LIST_CAPACITY: usize = 4096;

const DOF: usize = 6;
/// Tolerance on time comparisons [s] (clock rounding).
const EPS_S: f64 = 1e-9;
const DECADES: usize = 6;
const HIST_LO_S: f64 = 1e-6;
const HIST_BINS: usize = BINS_PER_DECADE * DECADES + 2;
/// Peak ring: 1 s at 500 Hz is 501 samples.
const PEAK_CAPACITY: usize = 1024;

/// What the control cycle reports about itself, every cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct CycleRecord {
    /// Controller cycles skipped before this one (the controller timestamp advanced by more
    /// than one 2 ms cycle) [-].
    pub(crate) missed: u32,
    /// Wall time from the state's arrival to the command's send [s]; None on the mock clock.
    pub(crate) latency_s: Option<f64>,
    /// Lateness of the cycle's wake-up against its deadline [s]; None on the mock clock.
    pub(crate) wake_jitter_s: Option<f64>,
    /// The planner's jerk limit in force this cycle [rad/s³] (largest over the joints).
    pub(crate) jerk_limit_rad_s3: f64,
    /// The planner's time-scaling factor s in [0, 1] [-] (1 when the plan runs at full speed).
    pub(crate) time_scale: f64,
}

/// A fixed log-spaced histogram of durations [s] (see the module docs for the resolution).
#[derive(Debug, Clone)]
pub(crate) struct LogHistogram {
    bins: [u64; HIST_BINS],
    n: u64,
    max_s: f64,
}

impl Default for LogHistogram {
    fn default() -> Self {
        Self {
            bins: [0; HIST_BINS],
            n: 0,
            max_s: f64::NEG_INFINITY,
        }
    }
}

impl LogHistogram {
    /// Bin of `x_s`: 0 below 1 µs, 1..=240 by decade fraction, 241 from 1 s.
    fn bin(x_s: f64) -> usize {
        if x_s.is_nan() || x_s < HIST_LO_S {
            return 0;
        }
        let k = ((x_s / HIST_LO_S).log10() * BINS_PER_DECADE as f64).floor();
        if k >= (HIST_BINS - 2) as f64 {
            HIST_BINS - 1
        } else {
            k as usize + 1
        }
    }

    /// Upper edge of bin `b` [s] (the maximum for the overflow bin).
    fn upper_edge_s(&self, b: usize) -> f64 {
        if b == 0 {
            HIST_LO_S
        } else if b >= HIST_BINS - 1 {
            self.max_s
        } else {
            HIST_LO_S * 10f64.powf(b as f64 / BINS_PER_DECADE as f64)
        }
    }

    /// Counts one value [s] (non-finite values are ignored).
    pub(crate) fn add(&mut self, x_s: f64) {
        if !x_s.is_finite() {
            return;
        }
        if let Some(c) = self.bins.get_mut(Self::bin(x_s)) {
            *c += 1;
        }
        self.n += 1;
        self.max_s = self.max_s.max(x_s);
    }

    /// Values counted.
    pub(crate) fn len(&self) -> u64 {
        self.n
    }

    /// The exact maximum [s]; `None` when empty.
    pub(crate) fn max_s(&self) -> Option<f64> {
        (self.n > 0).then_some(self.max_s)
    }

    /// The p-quantile (nearest rank, p in (0, 1]) as its bin's upper edge, capped at the
    /// maximum [s]; `None` when empty.
    pub(crate) fn quantile_s(&self, p: f64) -> Option<f64> {
        if self.n == 0 {
            return None;
        }
        let rank = ((p * self.n as f64).ceil() as u64).clamp(1, self.n);
        let mut seen = 0;
        for (b, &c) in self.bins.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Some(self.upper_edge_s(b).min(self.max_s).max(0.0));
            }
        }
        Some(self.max_s)
    }
}

/// Running sums and maxima of the executed jerk.
#[derive(Debug, Clone, Copy, Default)]
struct JerkStats {
    n: u64,
    sum_sq: [f64; DOF],
    max_abs: [f64; DOF],
}

impl JerkStats {
    fn add(&mut self, j: &[f64; DOF]) {
        self.n += 1;
        for ((s, m), &x) in self.sum_sq.iter_mut().zip(&mut self.max_abs).zip(j) {
            *s += x * x;
            *m = m.max(x.abs());
        }
    }
}

/// Jerk samples judged against the limit, and those over it.
#[derive(Debug, Clone, Copy, Default)]
struct ExceedCounts {
    judged: u64,
    exceeding: u64,
}

/// One joint's reversal detector: the sign and time of its last sample above the threshold.
#[derive(Debug, Clone, Copy, Default)]
struct ReversalDetector {
    last: Option<(f64, bool)>,
}

impl ReversalDetector {
    /// Feeds one sample; true when it completes a reversal.
    fn update(&mut self, t_s: f64, qd: f64) -> bool {
        if qd.is_nan() || qd.abs() <= REVERSAL_MIN_SPEED_RAD_S {
            return false;
        }
        let positive = qd > 0.0;
        let reversal = self
            .last
            .is_some_and(|(tl, pl)| pl != positive && t_s - tl <= REVERSAL_WINDOW_S + EPS_S);
        self.last = Some((t_s, positive));
        reversal
    }
}

/// A stop-and-go event (or a dip being watched).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Dip {
    /// When the speed fell below half the recent peak [s].
    pub(crate) start_s: f64,
    /// Until it was back at that level [s].
    pub(crate) duration_s: f64,
    /// The recent peak at the start [m/s].
    pub(crate) peak_m_s: f64,
    /// The lowest speed during the dip [m/s].
    pub(crate) min_m_s: f64,
    /// A sample of the dip was inside a stop window.
    pub(crate) inside_stop: bool,
}

#[derive(Debug, Clone, Copy)]
enum DipState {
    Armed,
    Dip { dip: Dip, level: f64 },
    Disarmed,
}

/// The stop-and-go detector (module docs, "Stop-and-go").
#[derive(Debug)]
struct StopAndGo {
    /// Monotonic (decreasing speed) ring of (t [s], v [m/s]) over the peak window.
    peak: VecDeque<(f64, f64)>,
    state: DipState,
}

impl StopAndGo {
    fn new() -> Self {
        Self {
            peak: VecDeque::with_capacity(PEAK_CAPACITY),
            state: DipState::Armed,
        }
    }

    /// Feeds one sample; returns a completed event.
    fn update(&mut self, t_s: f64, v: f64, inside: bool) -> Option<Dip> {
        if !v.is_finite() {
            return None;
        }
        while self.peak.back().is_some_and(|&(_, b)| b <= v) {
            self.peak.pop_back();
        }
        if self.peak.len() == self.peak.capacity() {
            self.peak.pop_front();
        }
        self.peak.push_back((t_s, v));
        while self
            .peak
            .front()
            .is_some_and(|&(tf, _)| tf < t_s - PEAK_WINDOW_S - EPS_S)
        {
            self.peak.pop_front();
        }
        let p = self.peak.front().map_or(v, |&(_, pv)| pv);
        match &mut self.state {
            DipState::Armed => {
                if p >= MIN_PEAK_M_S && v < 0.5 * p {
                    self.state = DipState::Dip {
                        dip: Dip {
                            start_s: t_s,
                            duration_s: 0.0,
                            peak_m_s: p,
                            min_m_s: v,
                            inside_stop: inside,
                        },
                        level: RECOVERY_SHARE * p,
                    };
                }
                None
            }
            DipState::Dip { dip, level } => {
                dip.inside_stop |= inside;
                dip.min_m_s = dip.min_m_s.min(v);
                let elapsed = t_s - dip.start_s;
                if v >= *level {
                    let event = (elapsed <= RECOVERY_S + EPS_S).then_some(Dip {
                        duration_s: elapsed,
                        ..*dip
                    });
                    self.state = if event.is_some() {
                        DipState::Armed
                    } else {
                        DipState::Disarmed
                    };
                    event
                } else {
                    if elapsed > RECOVERY_S + EPS_S {
                        self.state = DipState::Disarmed;
                    }
                    None
                }
            }
            DipState::Disarmed => {
                if v >= 0.5 * p {
                    self.state = DipState::Armed;
                }
                None
            }
        }
    }
}

/// A stop window (module docs, "Stop windows").
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct StopWindow {
    /// First stop cycle [s].
    pub(crate) start_s: f64,
    /// Last stop cycle [s].
    pub(crate) last_stop_s: f64,
    /// End: last stop + [`STOP_TAIL_S`], or the last cycle of the trial [s].
    pub(crate) end_s: f64,
    /// Cycles with a `Stopped` or `Halted` verdict.
    pub(crate) stop_cycles: u64,
    /// Bit `Requirement::index()` set for each requirement that stopped or halted in it.
    pub(crate) requirements: u16,
    /// The first stop's violation.
    pub(crate) first_violation: Violation,
    /// The first SAF-REQ-007 violation, if any.
    pub(crate) separation_violation: Option<Violation>,
    /// Minimum human distance over the window's cycles [m] (`None`: never tracked).
    pub(crate) min_human_distance_m: Option<f64>,
}

impl StopWindow {
    /// The window holds a SAF-REQ-007 stop (a real separation stop).
    pub(crate) fn is_separation(&self) -> bool {
        self.requirements & (1 << Requirement::Saf007Separation.index()) != 0
    }
}

/// The records of the cycle being gathered.
#[derive(Debug, Clone, Copy)]
struct Pending {
    t_s: f64,
    verdict: Option<Verdict>,
    qd: Option<[f64; DOF]>,
    jerk: Option<[f64; DOF]>,
    tcp_speed_m_s: Option<f64>,
    record: Option<CycleRecord>,
    distance_m: Option<Option<f64>>,
}

impl Pending {
    fn new(t_s: f64) -> Self {
        Self {
            t_s,
            verdict: None,
            qd: None,
            jerk: None,
            tcp_speed_m_s: None,
            record: None,
            distance_m: None,
        }
    }
}

/// Streaming motion-quality metrics of one trial (see the module docs).
#[derive(Debug)]
pub(crate) struct MotionMetrics {
    pending: Option<Pending>,
    last_cycle_s: Option<f64>,
    // Interventions: [reduced, stopped, halted] per requirement.
    interventions: [[u64; 3]; Requirement::COUNT],
    commands: u64,
    passed: u64,
    // Stop windows.
    open: Option<StopWindow>,
    windows: Vec<StopWindow>,
    window_counts: WindowCounts,
    // Jerk.
    history: [Option<(f64, [f64; DOF])>; 2],
    repeated_states: u64,
    state_samples: u64,
    jerk: [JerkStats; 2],
    exceed: [ExceedCounts; 2],
    jerk_limit_range: Option<(f64, f64)>,
    // Reversals: [overall, outside] per joint.
    reversal: [ReversalDetector; DOF],
    reversals: [[u64; DOF]; 2],
    // Stop-and-go.
    stop_and_go: StopAndGo,
    dips: [u64; 2],
    dip_list: Vec<Dip>,
    // Cycle records.
    records: u64,
    missed_total: u64,
    cycles_with_missed: u64,
    missed_max: u32,
    latency: LogHistogram,
    jitter: LogHistogram,
    time_scale_sum: f64,
    time_scale_n: u64,
    time_scale_min: f64,
    /// The robot side's own count of what it did with the servo commands (the in-process
    /// emulator only).
    robot_servo: Option<ServoStats>,
    /// The in-process emulator's own clock (emulator runs only).
    emulator_clock: Option<ClockStats>,
    /// How the threads were scheduled (RTDE robots only).
    scheduling: Option<SchedulingSummary>,
}

#[derive(Debug, Clone, Copy, Default)]
struct WindowCounts {
    total: u64,
    separation: u64,
    time_s: f64,
}

impl Default for MotionMetrics {
    fn default() -> Self {
        Self::new()
    }
}

/// Index of the overall and the outside-stops scope.
const ALL: usize = 0;
const OUTSIDE: usize = 1;

impl MotionMetrics {
    /// The robot side's servo statistics, as the in-process emulator counted them at the end
    /// of the trial (`motion.robot_servo`).
    pub(crate) fn set_robot_servo(&mut self, stats: ServoStats) {
        self.robot_servo = Some(stats);
    }

    /// How the in-process emulator's clock kept up with wall time, at the end of the trial
    /// (`motion.emulator_clock`).
    pub(crate) fn set_emulator_clock(&mut self, stats: ClockStats) {
        self.emulator_clock = Some(stats);
    }

    /// How the control thread, the RTDE I/O threads and the emulator's clock were scheduled
    /// (`motion.scheduling`).
    pub(crate) fn set_scheduling(&mut self, s: SchedulingSummary) {
        self.scheduling = Some(s);
    }

    /// Empty metrics with every buffer preallocated.
    pub(crate) fn new() -> Self {
        Self {
            pending: None,
            last_cycle_s: None,
            interventions: [[0; 3]; Requirement::COUNT],
            commands: 0,
            passed: 0,
            open: None,
            windows: Vec::with_capacity(LIST_CAPACITY),
            window_counts: WindowCounts::default(),
            history: [None; 2],
            repeated_states: 0,
            state_samples: 0,
            jerk: [JerkStats::default(); 2],
            exceed: [ExceedCounts::default(); 2],
            jerk_limit_range: None,
            reversal: [ReversalDetector::default(); DOF],
            reversals: [[0; DOF]; 2],
            stop_and_go: StopAndGo::new(),
            dips: [0; 2],
            dip_list: Vec::with_capacity(LIST_CAPACITY),
            records: 0,
            missed_total: 0,
            cycles_with_missed: 0,
            missed_max: 0,
            latency: LogHistogram::default(),
            jitter: LogHistogram::default(),
            time_scale_sum: 0.0,
            time_scale_n: 0,
            time_scale_min: f64::INFINITY,
            robot_servo: None,
            emulator_clock: None,
            scheduling: None,
        }
    }

    /// The pending cycle at `t_s`, evaluating the previous one if `t_s` starts a new cycle.
    fn at(&mut self, t_s: f64) -> &mut Pending {
        if self.pending.is_some_and(|p| p.t_s != t_s) {
            self.close();
        }
        self.pending.get_or_insert_with(|| Pending::new(t_s))
    }

    /// The robot state of the cycle at trial time `t_s` [s] (every state, not decimated).
    pub(crate) fn on_state(&mut self, t_s: f64, s: &RobotState) {
        self.state_samples += 1;
        let ts = s.timestamp_s;
        let qd = s.actual_qd;
        let v = &s.actual_tcp_speed;
        let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        // Jerk from the last two distinct states.
        if !ts.is_finite() || self.history[0].is_some_and(|(t1, _)| ts <= t1) {
            // A repeat (or a timestamp going back): not a new sample of the motion.
            self.repeated_states += 1;
            return;
        }
        let mut jerk = None;
        if let [Some((t1, qd1)), Some((t0, qd0))] = self.history {
            let (dt1, dt0) = (ts - t1, t1 - t0);
            let mut j = [0.0; DOF];
            for (((jk, v2), v1), v0) in j.iter_mut().zip(&qd).zip(&qd1).zip(&qd0) {
                let a1 = (v2 - v1) / dt1;
                let a0 = (v1 - v0) / dt0;
                *jk = (a1 - a0) / (0.5 * (dt1 + dt0));
            }
            jerk = Some(j);
        }
        self.history = [Some((ts, qd)), self.history[0]];
        let p = self.at(t_s);
        p.qd = Some(qd);
        p.jerk = jerk;
        p.tcp_speed_m_s = Some(speed);
    }

    /// The supervisor's verdict on the command of the cycle at `t_s` [s].
    pub(crate) fn on_verdict(&mut self, t_s: f64, v: &Verdict) {
        self.at(t_s).verdict = Some(*v);
    }

    /// The cycle record of the cycle at `t_s` [s].
    pub(crate) fn on_cycle(&mut self, t_s: f64, r: &CycleRecord) {
        self.at(t_s).record = Some(*r);
    }

    /// The minimum human distance of the cycle at `t_s` [m] (`None`: no human point tracked).
    pub(crate) fn on_distance(&mut self, t_s: f64, d: Option<f64>) {
        self.at(t_s).distance_m = Some(d);
    }

    /// The executed jerk of the cycle at `t_s`, max over the joints of |j| [rad/s³] (`None`
    /// before its state, or for the first two states).
    pub(crate) fn jerk_abs_max(&self, t_s: f64) -> Option<f64> {
        let p = self.pending.as_ref().filter(|p| p.t_s == t_s)?;
        p.jerk
            .map(|j| j.iter().fold(0.0_f64, |m, x| m.max(x.abs())))
    }

    fn close_window(&mut self, mut w: StopWindow, end_s: f64) {
        w.end_s = end_s.max(w.start_s);
        self.window_counts.total += 1;
        self.window_counts.time_s += w.end_s - w.start_s;
        if w.is_separation() {
            self.window_counts.separation += 1;
        }
        if self.windows.len() < self.windows.capacity() {
            self.windows.push(w);
        }
    }

    /// Evaluates the pending cycle.
    fn close(&mut self) {
        let Some(p) = self.pending.take() else {
            return;
        };
        let t = p.t_s;
        self.last_cycle_s = Some(t);
        // 1. Verdict: interventions and stop windows.
        let mut stop = None;
        if let Some(v) = p.verdict {
            self.commands += 1;
            let (slot, violation) = match v {
                Verdict::Passed => (None, None),
                Verdict::Reduced { violation, .. } => (Some(0), Some(violation)),
                Verdict::Stopped { violation } => (Some(1), Some(violation)),
                Verdict::Halted { violation } => (Some(2), Some(violation)),
            };
            match (slot, violation) {
                (Some(slot), Some(violation)) => {
                    let r = violation.requirement();
                    if let Some(c) = self
                        .interventions
                        .get_mut(r.index())
                        .and_then(|c| c.get_mut(slot))
                    {
                        *c += 1;
                    }
                    if slot > 0 {
                        stop = Some(violation);
                    }
                }
                _ => self.passed += 1,
            }
        }
        if let Some(w) = self.open
            && t - w.last_stop_s > STOP_TAIL_S + EPS_S
        {
            self.open = None;
            self.close_window(w, w.last_stop_s + STOP_TAIL_S);
        }
        if let Some(violation) = stop {
            let r = violation.requirement();
            let sep = (r == Requirement::Saf007Separation).then_some(violation);
            let w = self.open.get_or_insert(StopWindow {
                start_s: t,
                last_stop_s: t,
                end_s: t,
                stop_cycles: 0,
                requirements: 0,
                first_violation: violation,
                separation_violation: None,
                min_human_distance_m: None,
            });
            w.last_stop_s = t;
            w.stop_cycles += 1;
            w.requirements |= 1 << r.index();
            if w.separation_violation.is_none() {
                w.separation_violation = sep;
            }
        }
        let inside = self.open.is_some();
        if let (Some(w), Some(Some(d))) = (self.open.as_mut(), p.distance_m)
            && d.is_finite()
        {
            w.min_human_distance_m = Some(w.min_human_distance_m.map_or(d, |m| m.min(d)));
        }
        let scopes: &[usize] = if inside { &[ALL] } else { &[ALL, OUTSIDE] };

        // 2. Cycle record.
        if let Some(r) = p.record {
            self.records += 1;
            self.missed_total += u64::from(r.missed);
            if r.missed > 0 {
                self.cycles_with_missed += 1;
            }
            self.missed_max = self.missed_max.max(r.missed);
            if let Some(l) = r.latency_s {
                self.latency.add(l);
            }
            if let Some(j) = r.wake_jitter_s {
                self.jitter.add(j);
            }
            if r.time_scale.is_finite() {
                self.time_scale_sum += r.time_scale;
                self.time_scale_n += 1;
                self.time_scale_min = self.time_scale_min.min(r.time_scale);
            }
            if r.jerk_limit_rad_s3.is_finite() {
                let l = r.jerk_limit_rad_s3;
                self.jerk_limit_range = Some(
                    self.jerk_limit_range
                        .map_or((l, l), |(lo, hi)| (lo.min(l), hi.max(l))),
                );
            }
        }

        // 3. State: jerk, jerk limit, reversals, stop-and-go.
        if let Some(j) = p.jerk {
            let max_abs = j.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
            let limit = p
                .record
                .map(|r| r.jerk_limit_rad_s3)
                .filter(|l| l.is_finite() && *l > 0.0);
            for &s in scopes {
                if let Some(st) = self.jerk.get_mut(s) {
                    st.add(&j);
                }
                if let (Some(l), Some(e)) = (limit, self.exceed.get_mut(s)) {
                    e.judged += 1;
                    if max_abs > JERK_LIMIT_FACTOR * l {
                        e.exceeding += 1;
                    }
                }
            }
        }
        if let Some(qd) = p.qd {
            for (k, (det, &q)) in self.reversal.iter_mut().zip(&qd).enumerate() {
                if det.update(t, q) {
                    for &s in scopes {
                        if let Some(c) = self.reversals.get_mut(s).and_then(|r| r.get_mut(k)) {
                            *c += 1;
                        }
                    }
                }
            }
        }
        if let Some(v) = p.tcp_speed_m_s
            && let Some(d) = self.stop_and_go.update(t, v, inside)
        {
            self.dips[ALL] += 1;
            if !d.inside_stop {
                self.dips[OUTSIDE] += 1;
            }
            if self.dip_list.len() < self.dip_list.capacity() {
                self.dip_list.push(d);
            }
        }
    }

    /// Evaluates the last cycle and closes an open stop window at the last cycle.
    pub(crate) fn finish(&mut self) {
        self.close();
        if let Some(w) = self.open.take() {
            let end = self
                .last_cycle_s
                .unwrap_or(w.last_stop_s)
                .min(w.last_stop_s + STOP_TAIL_S);
            self.close_window(w, end);
        }
    }

    /// The stop-and-go events listed (at most [`LIST_CAPACITY`]).
    #[cfg(test)]
    pub(crate) fn dips(&self) -> &[Dip] {
        &self.dip_list
    }

    /// The `motion` object of `summary.json`. `debounced` holds the debounced safety events
    /// per requirement (by [`Requirement::index`]). Call after [`Self::finish`].
    pub(crate) fn summary(&self, debounced: &[u64; Requirement::COUNT]) -> MotionSummary {
        let mut by_requirement = BTreeMap::new();
        let mut total = RequirementCounts::default();
        for r in Requirement::ALL {
            let c = self.interventions.get(r.index()).copied().unwrap_or([0; 3]);
            let e = debounced.get(r.index()).copied().unwrap_or(0);
            let counts = RequirementCounts {
                reduced: c[0],
                stopped: c[1],
                halted: c[2],
                debounced_events: e,
            };
            total.reduced += counts.reduced;
            total.stopped += counts.stopped;
            total.halted += counts.halted;
            total.debounced_events += counts.debounced_events;
            by_requirement.insert(r.id().to_string(), counts);
        }
        let jerk = |s: usize| {
            let st = self.jerk.get(s).copied().unwrap_or_default();
            let some = st.n > 0;
            let n = st.n as f64;
            let per_joint_rms = st.sum_sq.map(|x| r6((x / n).sqrt()));
            JerkSummary {
                samples: st.n,
                rms_rad_s3: some
                    .then(|| r6((st.sum_sq.iter().sum::<f64>() / (n * DOF as f64)).sqrt())),
                max_rad_s3: some.then(|| r6(st.max_abs.iter().fold(0.0_f64, |m, x| m.max(*x)))),
                rms_per_joint_rad_s3: some.then_some(per_joint_rms),
                max_per_joint_rad_s3: some.then(|| st.max_abs.map(r6)),
            }
        };
        let exceed = |s: usize| {
            let e = self.exceed.get(s).copied().unwrap_or_default();
            ExceedSummary {
                judged: e.judged,
                exceeding: e.exceeding,
                share: (e.judged > 0).then(|| r6(e.exceeding as f64 / e.judged as f64)),
            }
        };
        let reversals = |s: usize| {
            let per_joint = self.reversals.get(s).copied().unwrap_or([0; DOF]);
            ReversalCounts {
                total: per_joint.iter().sum(),
                per_joint,
            }
        };
        let us = |h: &LogHistogram| {
            (h.len() > 0).then(|| Percentiles {
                samples: h.len(),
                p50: h.quantile_s(0.5).map_or(f64::NAN, |x| r6(x * 1e6)),
                p99: h.quantile_s(0.99).map_or(f64::NAN, |x| r6(x * 1e6)),
                max: h.max_s().map_or(f64::NAN, |x| r6(x * 1e6)),
            })
        };
        let windows = self
            .windows
            .iter()
            .map(|w| StopWindowSummary {
                start_s: r6(w.start_s),
                duration_s: r6(w.end_s - w.start_s),
                stop_cycles: w.stop_cycles,
                requirements: Requirement::ALL
                    .iter()
                    .filter(|r| w.requirements & (1 << r.index()) != 0)
                    .map(|r| r.id())
                    .collect(),
                separation: w.is_separation(),
                violation: w
                    .separation_violation
                    .unwrap_or(w.first_violation)
                    .to_string(),
                min_human_distance_m: w.min_human_distance_m.map(r6),
            })
            .collect();
        MotionSummary {
            control_cycles: self.commands,
            state_samples: self.state_samples,
            repeated_states: self.repeated_states,
            interventions: Interventions {
                commands: self.commands,
                passed: self.passed,
                total,
                by_requirement,
            },
            stop_windows: StopWindowsSummary {
                tail_s: STOP_TAIL_S,
                count: self.window_counts.total,
                separation: self.window_counts.separation,
                other: self.window_counts.total - self.window_counts.separation,
                time_s: r6(self.window_counts.time_s),
                listed: self.windows.len() as u64,
                windows,
            },
            jerk: JerkScopes {
                overall: jerk(ALL),
                outside_stops: jerk(OUTSIDE),
            },
            jerk_limit: JerkLimitSummary {
                factor: JERK_LIMIT_FACTOR,
                min_rad_s3: self.jerk_limit_range.map(|r| r6(r.0)),
                max_rad_s3: self.jerk_limit_range.map(|r| r6(r.1)),
                overall: exceed(ALL),
                outside_stops: exceed(OUTSIDE),
            },
            velocity_reversals: VelocityReversals {
                min_speed_rad_s: REVERSAL_MIN_SPEED_RAD_S,
                window_s: REVERSAL_WINDOW_S,
                overall: reversals(ALL),
                outside_stops: reversals(OUTSIDE),
            },
            stop_and_go: StopAndGoSummary {
                peak_window_s: PEAK_WINDOW_S,
                min_peak_m_s: MIN_PEAK_M_S,
                recovery_s: RECOVERY_S,
                overall: self.dips[ALL],
                outside_stops: self.dips[OUTSIDE],
                events_outside_stops: self
                    .dip_list
                    .iter()
                    .filter(|d| !d.inside_stop)
                    .map(|d| DipSummary {
                        start_s: r6(d.start_s),
                        duration_s: r6(d.duration_s),
                        peak_m_s: r6(d.peak_m_s),
                        min_m_s: r6(d.min_m_s),
                    })
                    .collect(),
            },
            cycles: CycleSummary {
                records: self.records,
                missed_total: self.missed_total,
                cycles_with_missed: self.cycles_with_missed,
                missed_max: self.missed_max,
                latency_us: us(&self.latency),
                wake_jitter_us: us(&self.jitter),
                time_scale_min: (self.time_scale_n > 0).then(|| r6(self.time_scale_min)),
                time_scale_mean: (self.time_scale_n > 0)
                    .then(|| r6(self.time_scale_sum / self.time_scale_n as f64)),
            },
            robot_servo: self.robot_servo.map(|s| RobotServoSummary {
                commands: s.commands,
                late_by_cycles: s.late,
                extrapolated_cycles: s.extrapolated_cycles,
                early_cycles: s.early_cycles,
                held_cycles: s.held_cycles,
                holds: s.holds,
            }),
            emulator_clock: self.emulator_clock.map(|c| EmulatorClockSummary {
                cycles_elapsed: c.cycles_elapsed,
                cycles_run: c.cycles_run,
                cycles_late: c.cycles_late,
                cycles_dropped: c.cycles_dropped,
                max_behind_cycles: c.max_behind_cycles,
                cycles_slewed: c.cycles_slewed,
                bursts: c.bursts,
                holds_in_bursts: c.holds_in_bursts,
                cycles_waited: c.cycles_waited,
                waits: c.waits,
                waits_timed_out: c.waits_timed_out,
            }),
            scheduling: self.scheduling.clone(),
        }
    }
}

/// `motion.robot_servo`: what the robot side did with the servo commands, as the in-process
/// emulator counts it every controller cycle (`robot_io::emulator::ServoStats`). Only for
/// `--robot emulator` (absent on `--robot sim`, which has no RTDE link, and on a real UR5e,
/// which does not tell).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct RobotServoSummary {
    /// Servo commands the program received.
    pub(crate) commands: u64,
    /// Index k: commands that arrived k program cycles after the tick they were meant for
    /// (0: on time; the last index: 16 or more).
    pub(crate) late_by_cycles: [u64; SERVO_LATE_BINS],
    /// Cycles in which the program extrapolated the target in force within its bound.
    pub(crate) extrapolated_cycles: u64,
    /// Cycles in which the target in force was meant for a later tick (evaluated back).
    pub(crate) early_cycles: u64,
    /// Cycles in which the moving target in force was older than the bound and held (the arm
    /// brakes towards it).
    pub(crate) held_cycles: u64,
    /// Separate runs of held cycles.
    pub(crate) holds: u64,
}

/// `motion.emulator_clock`: how the in-process emulator's own clock kept up with wall time
/// (`robot_io::emulator::ClockStats`), so that what the emulator's host did is told apart
/// from what the client did. Emulator runs only.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct EmulatorClockSummary {
    /// Controller cycles due since the emulator started (wall time × speedup / 2 ms).
    pub(crate) cycles_elapsed: u64,
    /// Cycles run.
    pub(crate) cycles_run: u64,
    /// Cycles run late, in a burst (a backlog beyond the 20 ms the clock slews).
    pub(crate) cycles_late: u64,
    /// Cycles never run (the backlog beyond the per-wake bound).
    pub(crate) cycles_dropped: u64,
    /// The largest backlog at one wake.
    pub(crate) max_behind_cycles: u64,
    /// Cycles run one per wake while the clock worked off a backlog at 1.25 × its rate.
    pub(crate) cycles_slewed: u64,
    /// Wakes that ran more than one cycle.
    pub(crate) bursts: u64,
    /// Servo holds that began in such a burst (the emulator late, not the client).
    pub(crate) holds_in_bursts: u64,
    /// Cycles not run while the sped-up clock waited for a late servo command (virtual time
    /// stood still; `[emulator] wait_for_client_ms`).
    pub(crate) cycles_waited: u64,
    /// Times the clock began such a wait.
    pub(crate) waits: u64,
    /// Waits that reached the bound: the clock then ran on as a controller's does.
    pub(crate) waits_timed_out: u64,
}

/// `motion` in `summary.json` (README.md, "Motion quality metrics").
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct MotionSummary {
    /// Control cycles judged by the supervisor (one command each).
    pub(crate) control_cycles: u64,
    /// Robot states received (every one, not decimated).
    pub(crate) state_samples: u64,
    /// States whose timestamp did not advance (skipped for jerk and reversals).
    pub(crate) repeated_states: u64,
    /// Supervisor interventions, raw per command and debounced.
    pub(crate) interventions: Interventions,
    /// Stop windows.
    pub(crate) stop_windows: StopWindowsSummary,
    /// Executed jerk.
    pub(crate) jerk: JerkScopes,
    /// Executed jerk against the planner's limit.
    pub(crate) jerk_limit: JerkLimitSummary,
    /// Joint velocity reversals.
    pub(crate) velocity_reversals: VelocityReversals,
    /// Stop-and-go events.
    pub(crate) stop_and_go: StopAndGoSummary,
    /// What the cycles reported about themselves.
    pub(crate) cycles: CycleSummary,
    /// What the robot side did with the servo commands (emulator runs only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) robot_servo: Option<RobotServoSummary>,
    /// How the emulator's own clock kept up (emulator runs only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) emulator_clock: Option<EmulatorClockSummary>,
    /// How the threads a control cycle waits on were scheduled (RTDE robots only: the
    /// `[realtime]` priorities, or why the OS refused them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) scheduling: Option<SchedulingSummary>,
}

/// Counts of one requirement.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub(crate) struct RequirementCounts {
    /// Commands reduced (raw, per command).
    pub(crate) reduced: u64,
    /// Commands replaced by a stop (raw, per command).
    pub(crate) stopped: u64,
    /// Commands while halted (raw, per command).
    pub(crate) halted: u64,
    /// Debounced safety events (the `safety_events` of the summary).
    pub(crate) debounced_events: u64,
}

/// Supervisor interventions.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Interventions {
    /// Commands judged.
    pub(crate) commands: u64,
    /// Commands passed unchanged.
    pub(crate) passed: u64,
    /// Over all requirements.
    pub(crate) total: RequirementCounts,
    /// Per requirement (every `SAF-REQ-nnn`, zeros included).
    pub(crate) by_requirement: BTreeMap<String, RequirementCounts>,
}

/// Stop windows.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct StopWindowsSummary {
    /// A window ends this long after its last stop [s].
    pub(crate) tail_s: f64,
    /// Windows.
    pub(crate) count: u64,
    /// Windows with a SAF-REQ-007 stop (real separation stops).
    pub(crate) separation: u64,
    /// Windows without one.
    pub(crate) other: u64,
    /// Total time inside windows [s].
    pub(crate) time_s: f64,
    /// Windows listed below (all of them unless more than the list capacity).
    pub(crate) listed: u64,
    /// Each window.
    pub(crate) windows: Vec<StopWindowSummary>,
}

/// One stop window.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct StopWindowSummary {
    /// First stop cycle [s].
    pub(crate) start_s: f64,
    /// To its end [s].
    pub(crate) duration_s: f64,
    /// Stop or halt cycles in it.
    pub(crate) stop_cycles: u64,
    /// Requirements that stopped or halted in it.
    pub(crate) requirements: Vec<&'static str>,
    /// A SAF-REQ-007 stop is in it.
    pub(crate) separation: bool,
    /// The first SAF-REQ-007 violation (else the first violation), as the supervisor words it:
    /// the human point, the arm point or link, the distance and the required S_p.
    pub(crate) violation: String,
    /// Minimum human–robot distance over the window [m]; `null` if never tracked.
    pub(crate) min_human_distance_m: Option<f64>,
}

/// Executed jerk, overall and outside stops.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct JerkScopes {
    /// Every jerk sample.
    pub(crate) overall: JerkSummary,
    /// Samples of cycles outside stop windows.
    pub(crate) outside_stops: JerkSummary,
}

/// Jerk statistics.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct JerkSummary {
    /// Jerk samples (one per state from the third).
    pub(crate) samples: u64,
    /// RMS over joints and samples [rad/s³].
    pub(crate) rms_rad_s3: Option<f64>,
    /// Max |j| over joints and samples [rad/s³].
    pub(crate) max_rad_s3: Option<f64>,
    /// RMS per joint [rad/s³].
    pub(crate) rms_per_joint_rad_s3: Option<[f64; DOF]>,
    /// Max |j| per joint [rad/s³].
    pub(crate) max_per_joint_rad_s3: Option<[f64; DOF]>,
}

/// Jerk against the planner's limit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct JerkLimitSummary {
    /// A sample exceeds above this factor × the limit [-].
    pub(crate) factor: f64,
    /// Smallest limit in force [rad/s³].
    pub(crate) min_rad_s3: Option<f64>,
    /// Largest limit in force [rad/s³].
    pub(crate) max_rad_s3: Option<f64>,
    /// Every judged sample.
    pub(crate) overall: ExceedSummary,
    /// Samples outside stop windows.
    pub(crate) outside_stops: ExceedSummary,
}

/// Samples over the limit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct ExceedSummary {
    /// Jerk samples judged (their cycle had a limit).
    pub(crate) judged: u64,
    /// Of them, over factor × limit.
    pub(crate) exceeding: u64,
    /// exceeding / judged [-].
    pub(crate) share: Option<f64>,
}

/// Velocity reversals.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct VelocityReversals {
    /// |q̇| above which a sample counts [rad/s].
    pub(crate) min_speed_rad_s: f64,
    /// Both sides within [s].
    pub(crate) window_s: f64,
    /// Every reversal.
    pub(crate) overall: ReversalCounts,
    /// Reversals completed outside stop windows.
    pub(crate) outside_stops: ReversalCounts,
}

/// Reversal counts.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct ReversalCounts {
    /// Over the joints.
    pub(crate) total: u64,
    /// Per joint (base to wrist 3).
    pub(crate) per_joint: [u64; DOF],
}

/// Stop-and-go events.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct StopAndGoSummary {
    /// The recent peak's trailing window [s].
    pub(crate) peak_window_s: f64,
    /// Smallest recent peak that starts a dip [m/s].
    pub(crate) min_peak_m_s: f64,
    /// Recovery within [s].
    pub(crate) recovery_s: f64,
    /// Every event.
    pub(crate) overall: u64,
    /// Events with no sample inside a stop window.
    pub(crate) outside_stops: u64,
    /// Those events (up to the list capacity).
    pub(crate) events_outside_stops: Vec<DipSummary>,
}

/// One stop-and-go event.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct DipSummary {
    /// Start [s].
    pub(crate) start_s: f64,
    /// Until recovered [s].
    pub(crate) duration_s: f64,
    /// Recent peak [m/s].
    pub(crate) peak_m_s: f64,
    /// Lowest speed [m/s].
    pub(crate) min_m_s: f64,
}

/// Cycle records.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct CycleSummary {
    /// Cycle records received.
    pub(crate) records: u64,
    /// Controller cycles missed, in total.
    pub(crate) missed_total: u64,
    /// Cycles that followed at least one missed cycle.
    pub(crate) cycles_with_missed: u64,
    /// Most cycles missed before one cycle.
    pub(crate) missed_max: u32,
    /// State-to-send latency [µs]; `null` on the mock clock.
    pub(crate) latency_us: Option<Percentiles>,
    /// Wake-up lateness [µs]; `null` on the mock clock.
    pub(crate) wake_jitter_us: Option<Percentiles>,
    /// Smallest planner time scale [-].
    pub(crate) time_scale_min: Option<f64>,
    /// Mean planner time scale over the cycles [-].
    pub(crate) time_scale_mean: Option<f64>,
}

/// Histogram percentiles (module docs: bin upper edges, capped at the maximum).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Percentiles {
    /// Values.
    pub(crate) samples: u64,
    /// Median [µs].
    pub(crate) p50: f64,
    /// 99th percentile [µs].
    pub(crate) p99: f64,
    /// Exact maximum [µs].
    pub(crate) max: f64,
}

/// Index of a requirement id (`SAF-REQ-nnn`) in [`Requirement::ALL`].
pub(crate) fn requirement_index(id: &str) -> Option<usize> {
    Requirement::ALL.iter().position(|r| r.id() == id)
}

#[cfg(test)]
mod tests {
    use super::*;
    use safety::{ArmLink, BodyPart};

    const H: f64 = 0.002;

    fn state(ts: f64, qd: [f64; DOF], tcp_speed: f64) -> RobotState {
        RobotState {
            timestamp_s: ts,
            actual_qd: qd,
            actual_tcp_speed: [tcp_speed, 0.0, 0.0, 0.0, 0.0, 0.0],
            ..RobotState::default()
        }
    }

    fn record(missed: u32, latency_s: Option<f64>, jerk_limit: f64) -> CycleRecord {
        CycleRecord {
            missed,
            latency_s,
            wake_jitter_s: None,
            jerk_limit_rad_s3: jerk_limit,
            time_scale: 1.0,
        }
    }

    fn separation(distance_m: f64) -> Violation {
        Violation::Separation {
            part: BodyPart::LeftHand,
            link: ArmLink::Gripper,
            distance_m,
            required_m: 0.35,
        }
    }

    fn stopped_007() -> Verdict {
        Verdict::Stopped {
            violation: separation(0.2),
        }
    }

    fn near(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    fn summary(m: &mut MotionMetrics) -> MotionSummary {
        m.finish();
        m.summary(&[0; Requirement::COUNT])
    }

    /// A sine velocity has a known jerk. Worked by hand: joints 0 and 1 follow
    /// q̇ = A sin(ωt), ω = 2π rad/s, A = 0.1 and 0.2 rad/s, sampled every h = 2 ms over two
    /// periods (states k = 0..=1000). The central second difference of a sine is exact up to
    /// c = (sin x / x)² with x = ωh/2 = 0.0062832: c = 0.99998684, so the jerk sample of the
    /// middle state m is −A ω² c sin(ω h m), ω² = 39.478418. The 999 samples (m = 1..=999)
    /// have Σ sin² = 500 (two full periods; sin² 0 = 0), so
    /// RMS₀ = 0.1 · 39.478418 · 0.99998684 · √(500/999) = 2.792906 rad/s³, RMS₁ = 2 RMS₀ =
    /// 5.585811, max₀ = 0.1 ω² c = 3.947790 (m = 125 is a quarter period), max₁ = 7.895580;
    /// over the six joints RMS = RMS₀ √((1 + 4)/6) = 2.549562.
    #[test]
    fn sine_velocity_gives_the_hand_computed_rms_and_max_jerk() {
        let mut m = MotionMetrics::new();
        let w = 2.0 * std::f64::consts::PI;
        for k in 0..=1000u32 {
            let t = f64::from(k) * H;
            let s = (w * t).sin();
            m.on_state(t, &state(t, [0.1 * s, 0.2 * s, 0.0, 0.0, 0.0, 0.0], 0.0));
            m.on_verdict(t, &Verdict::Passed);
        }
        let s = summary(&mut m);
        let j = &s.jerk.overall;
        assert_eq!(j.samples, 999);
        let rms = j.rms_per_joint_rad_s3.unwrap();
        let max = j.max_per_joint_rad_s3.unwrap();
        assert!(near(rms[0], 2.792906, 2e-6), "{rms:?}");
        assert!(near(rms[1], 5.585811, 2e-6), "{rms:?}");
        assert_eq!(rms[2], 0.0);
        assert!(near(max[0], 3.947790, 2e-6), "{max:?}");
        assert!(near(max[1], 7.895580, 2e-6), "{max:?}");
        assert!(near(j.rms_rad_s3.unwrap(), 2.549562, 2e-6), "{j:?}");
        assert_eq!(j.max_rad_s3, Some(max[1]));
        // No stop: outside stops is everything.
        assert_eq!(&s.jerk.outside_stops, j);
        // The sine itself reverses at 0.5, 1.0 and 1.5 s; around each crossing joint 0 spends
        // 2 asin(0.03/0.1)/ω = 0.097 s at |q̇| ≤ 0.03 (joint 1 less), under 0.3 s: 3 each.
        assert_eq!(s.velocity_reversals.overall.per_joint, [3, 3, 0, 0, 0, 0]);
    }

    /// The real Δt is used. Worked by hand: q̇ = t²/2 on every joint has jerk d²q̇/dt² = 1
    /// rad/s³ exactly, and the three-point formula is exact for a quadratic whatever the
    /// spacing: with states at 0, 2, 8 (two cycles missed), 10, 34 (eleven missed) and 36 ms,
    /// e.g. at 8 ms: ((0.000032 − 0.000002)/0.006 − (0.000002 − 0)/0.002) / 0.004 =
    /// (0.005 − 0.001) / 0.004 = 1. A repeated state (same timestamp) is skipped.
    #[test]
    fn jerk_uses_the_actual_sample_spacing_and_skips_repeated_states() {
        let mut m = MotionMetrics::new();
        let times_ms = [0.0, 2.0, 8.0, 8.0, 10.0, 34.0, 36.0];
        for (k, ms) in times_ms.iter().enumerate() {
            let ts = ms / 1000.0;
            let q = 0.5 * ts * ts;
            // Trial time advances even for the repeat (a new cycle with a stale sample).
            m.on_state(k as f64 * H, &state(ts, [q; DOF], 0.0));
        }
        let s = summary(&mut m);
        assert_eq!(s.repeated_states, 1);
        assert_eq!(s.state_samples, 7);
        let j = &s.jerk.overall;
        assert_eq!(j.samples, 4, "six distinct states give four jerk samples");
        assert!(near(j.rms_rad_s3.unwrap(), 1.0, 1e-6), "{j:?}");
        assert!(near(j.max_rad_s3.unwrap(), 1.0, 1e-6), "{j:?}");
    }

    /// Jerk over 1.1 × the limit. Worked by hand: the same q̇ = t²/2 (jerk 1 rad/s³) at 2 ms;
    /// cycles alternate a limit of 0.95 (1.1 × 0.95 = 1.045 ≥ 1: fine) and 0.9 (0.99 < 1:
    /// exceeding). 10 states → 8 jerk samples (cycles 2..=9): cycles 3, 5, 7, 9 have 0.9.
    #[test]
    fn jerk_over_1_1_times_the_limit_is_counted() {
        let mut m = MotionMetrics::new();
        for k in 0..10u32 {
            let t = f64::from(k) * H;
            m.on_state(t, &state(t, [0.5 * t * t; DOF], 0.0));
            let limit = if k % 2 == 0 { 0.95 } else { 0.9 };
            m.on_cycle(t, &record(0, None, limit));
        }
        let s = summary(&mut m);
        assert_eq!(s.jerk_limit.overall.judged, 8);
        assert_eq!(s.jerk_limit.overall.exceeding, 4);
        assert_eq!(s.jerk_limit.overall.share, Some(0.5));
        assert_eq!(s.jerk_limit.min_rad_s3, Some(0.9));
        assert_eq!(s.jerk_limit.max_rad_s3, Some(0.95));
    }

    /// Feeds joint 0's velocity profile, 2 ms cycles, and a stop verdict at `stop_at` (k).
    fn reversal_profile(stop_at: Option<u32>) -> MotionSummary {
        let mut m = MotionMetrics::new();
        for k in 0..600u32 {
            let t = f64::from(k) * H;
            // By hand: 0–0.1 s +0.05; 0.1–0.2 s −0.05 (reversal 1 at 0.1 s: the last +0.05 was
            // 2 ms before); 0.2–0.6 s +0.05 (reversal 2 at 0.2 s); 0.6–0.8 s +0.02 and
            // 0.8–1.0 s −0.02 (a sign change, but |q̇| ≤ 0.03: none); 1.0–1.2 s −0.05 (the last
            // sample above 0.03 was +0.05 at 0.598 s, 0.402 s before: more than 0.3 s, none).
            let v = match k {
                0..50 => 0.05,
                50..100 => -0.05,
                100..300 => 0.05,
                300..400 => 0.02,
                400..500 => -0.02,
                _ => -0.05,
            };
            m.on_state(t, &state(t, [v, 0.01, 0.0, 0.0, 0.0, 0.0], 0.0));
            let verdict = if Some(k) == stop_at {
                stopped_007()
            } else {
                Verdict::Passed
            };
            m.on_verdict(t, &verdict);
        }
        summary(&mut m)
    }

    #[test]
    fn exactly_two_velocity_reversals_are_counted() {
        let s = reversal_profile(None);
        let r = &s.velocity_reversals;
        assert_eq!(r.overall.per_joint, [2, 0, 0, 0, 0, 0]);
        assert_eq!(r.overall.total, 2);
        assert_eq!(r.outside_stops.total, 2);
        // A stop at 0.2 s puts reversal 2 (completed at 0.2 s) inside its window.
        let s = reversal_profile(Some(100));
        assert_eq!(s.velocity_reversals.overall.total, 2);
        assert_eq!(s.velocity_reversals.outside_stops.total, 1);
        assert_eq!(s.stop_windows.count, 1);
    }

    /// Stop-and-go. Worked by hand on a TCP speed profile at 2 ms (trial time = k · 2 ms):
    /// - 0–1 s at 0.2 m/s, then 0.05 m/s for 1.0–1.2 s: below 0.1 (half the recent peak
    ///   0.2) at 1.0 s, back at 0.2 ≥ 0.16 (0.8 × the peak) at 1.2 s: an event of 0.2 s,
    ///   outside stops;
    /// - 1.2–3 s at 0.2, then 0 for 3.0–3.8 s: a dip from 3.0 s that has not recovered
    ///   0.5 s later: no event (the arm stopped); back at 0.2 at 3.8 s re-arms;
    /// - 3.8–5 s at 0.2, then 0.05 for 5.0–5.1 s with a SAF-REQ-007 stop at 5.0 s: an event
    ///   of 0.1 s, but inside the stop window [5.0, 6.0] s;
    /// - 5.1–7 s at 0.2.
    ///
    /// So 2 events overall, 1 outside stops (at 1.0 s, 0.2 s, peak 0.2, min 0.05).
    #[test]
    fn a_quick_dip_is_stop_and_go_a_long_one_or_one_in_a_stop_window_is_not() {
        let mut m = MotionMetrics::new();
        for k in 0..3500u32 {
            let t = f64::from(k) * H;
            let v = match k {
                500..600 | 2500..2550 => 0.05,
                1500..1900 => 0.0,
                _ => 0.2,
            };
            m.on_state(t, &state(t, [0.0; DOF], v));
            let verdict = if k == 2500 {
                stopped_007()
            } else {
                Verdict::Passed
            };
            m.on_verdict(t, &verdict);
        }
        let s = summary(&mut m);
        let g = &s.stop_and_go;
        assert_eq!((g.overall, g.outside_stops), (2, 1), "{g:?}");
        let e = &g.events_outside_stops[0];
        assert!(
            near(e.start_s, 1.0, 1e-6) && near(e.duration_s, 0.2, 1e-6),
            "{e:?}"
        );
        assert_eq!((e.peak_m_s, e.min_m_s), (0.2, 0.05));
        let inside = m.dips()[1];
        assert!(
            inside.inside_stop && near(inside.start_s, 5.0, 1e-6),
            "{inside:?}"
        );
    }

    /// A speed that falls just below half its peak and hovers there (0.2 m/s, then 0.099 and
    /// 0.105 m/s alternating every 50 ms for 0.4 s, then 0.11 m/s) never gets back to 0.8 × 0.2
    /// = 0.16 m/s within 0.5 s: no event. Back at 0.2 m/s 0.3 s after a dip to 0.05 m/s
    /// (k = 1500): an event.
    #[test]
    fn a_speed_hovering_about_half_its_peak_is_no_stop_and_go() {
        let mut m = MotionMetrics::new();
        for k in 0..2500u32 {
            let t = f64::from(k) * H;
            let v = match k {
                0..500 => 0.2,
                500..700 if (k / 25) % 2 == 0 => 0.099,
                500..700 => 0.105,
                700..1000 => 0.11,
                1000..1500 => 0.2,
                1500..1650 => 0.05,
                _ => 0.2,
            };
            m.on_state(t, &state(t, [0.0; DOF], v));
            m.on_verdict(t, &Verdict::Passed);
        }
        let s = summary(&mut m);
        let g = &s.stop_and_go;
        assert_eq!((g.overall, g.outside_stops), (1, 1), "{g:?}");
        assert!(near(g.events_outside_stops[0].start_s, 3.0, 1e-6), "{g:?}");
    }

    /// Interventions and stop windows. Worked by hand on 5 s of 2 ms cycles (k = 0..2500):
    /// a SAF-REQ-005 reduction at k = 100; SAF-REQ-007 stops at 1.0 s and 1.5 s (0.5 s
    /// apart: one window, to 1.5 + 1.0 = 2.5 s, 1.5 s long); a SAF-REQ-004 stop at 3.0 s and
    /// a SAF-REQ-010 halt at 3.002 s (one window to 4.002 s: 1.002 s); a SAF-REQ-007 stop at
    /// 4.8 s whose window the trial's end (last cycle 4.998 s) cuts to 0.198 s. The human
    /// distance is 0.5 m except 0.2 m at k = 600 (1.2 s, inside the first window), and
    /// untracked from 2.8 s to 4.2 s (the second window never sees it). Windows: 3, two of
    /// them separation; time inside 1.5 + 1.002 + 0.198 = 2.7 s.
    #[test]
    fn interventions_are_counted_per_command_and_stop_windows_per_run() {
        let mut m = MotionMetrics::new();
        for k in 0..2500u32 {
            let t = f64::from(k) * H;
            let verdict = match k {
                100 => Verdict::Reduced {
                    scale: 0.8,
                    violation: Violation::TcpSpeed {
                        value_m_s: 0.3,
                        limit_m_s: 0.25,
                    },
                },
                500 | 750 | 2400 => stopped_007(),
                1500 => Verdict::Stopped {
                    violation: Violation::JointAcceleration {
                        joint: 2,
                        value_rad_s2: 4.0,
                        limit_rad_s2: 3.0,
                    },
                },
                1501 => Verdict::Halted {
                    violation: Violation::RobotSafetyStop {
                        safety_mode: 3,
                        safety_status_bits: 4,
                    },
                },
                _ => Verdict::Passed,
            };
            m.on_verdict(t, &verdict);
            let d = match k {
                600 => Some(0.2),
                1400..2100 => None,
                _ => Some(0.5),
            };
            m.on_distance(t, d);
        }
        m.finish();
        let mut debounced = [0; Requirement::COUNT];
        debounced[Requirement::Saf007Separation.index()] = 3;
        let s = m.summary(&debounced);
        let i = &s.interventions;
        // Six commands were not passed: k = 100, 500, 750, 1500, 1501, 2400.
        assert_eq!((i.commands, i.passed), (2500, 2494));
        let c = |id: &str| i.by_requirement[id];
        assert_eq!(c("SAF-REQ-005").reduced, 1);
        assert_eq!(c("SAF-REQ-007").stopped, 3);
        assert_eq!(c("SAF-REQ-007").debounced_events, 3);
        assert_eq!(c("SAF-REQ-004").stopped, 1);
        assert_eq!(c("SAF-REQ-010").halted, 1);
        assert_eq!(c("SAF-REQ-003"), RequirementCounts::default());
        assert_eq!(i.by_requirement.len(), 12, "every requirement is listed");
        assert_eq!(
            (i.total.reduced, i.total.stopped, i.total.halted),
            (1, 4, 1)
        );

        let w = &s.stop_windows;
        assert_eq!((w.count, w.separation, w.other, w.listed), (3, 2, 1, 3));
        assert!(near(w.time_s, 2.7, 1e-6), "{w:?}");
        let [a, b, c] = [&w.windows[0], &w.windows[1], &w.windows[2]];
        assert!(
            near(a.start_s, 1.0, 1e-6) && near(a.duration_s, 1.5, 1e-6),
            "{a:?}"
        );
        assert_eq!((a.stop_cycles, a.separation), (2, true));
        assert_eq!(a.requirements, ["SAF-REQ-007"]);
        assert_eq!(a.violation, separation(0.2).to_string());
        // The supervisor's wording names the body part and the link.
        assert!(
            a.violation.contains(&BodyPart::LeftHand.to_string()),
            "{}",
            a.violation
        );
        assert!(
            a.violation.contains(&ArmLink::Gripper.to_string()),
            "{}",
            a.violation
        );
        assert_eq!(a.min_human_distance_m, Some(0.2));
        assert!(
            near(b.start_s, 3.0, 1e-6) && near(b.duration_s, 1.002, 1e-6),
            "{b:?}"
        );
        assert_eq!(b.requirements, ["SAF-REQ-004", "SAF-REQ-010"]);
        assert!(!b.separation);
        assert_eq!(b.min_human_distance_m, None);
        assert!(near(c.duration_s, 0.198, 1e-6), "{c:?}");
        assert_eq!(c.min_human_distance_m, Some(0.5));
    }

    /// Missed cycles and latency percentiles. Worked by hand: missed = 0, 0, 2, 0, 1, then
    /// 0 (100 records): 3 in total, 2 cycles after a gap, at most 2. Latencies 1, 2, …,
    /// 100 µs: the median (nearest rank 50) is 50 µs, in bin [10^(67/40), 10^(68/40)) µs =
    /// [47.32, 50.12) µs, reported as its upper edge 10^1.7 = 50.118723 µs; p99 (rank 99: 99
    /// µs) is in [94.41, 100) µs, whose edge 100 µs is also the maximum. No jitter values (mock
    /// clock): `null`.
    #[test]
    fn robot_servo_and_emulator_clock_statistics_are_passed_through_and_absent_without_an_emulator()
    {
        let mut m = MotionMetrics::new();
        let json = serde_json::to_value(summary(&mut m)).unwrap();
        assert!(json.get("robot_servo").is_none(), "{json}");
        assert!(json.get("emulator_clock").is_none(), "{json}");
        let mut late = [0; SERVO_LATE_BINS];
        late[0] = 90;
        late[3] = 7;
        late[SERVO_LATE_BINS - 1] = 3;
        let mut m = MotionMetrics::new();
        m.set_robot_servo(ServoStats {
            commands: 100,
            late,
            extrapolated_cycles: 40,
            early_cycles: 5,
            held_cycles: 12,
            holds: 2,
        });
        let json = serde_json::to_value(summary(&mut m)).unwrap();
        let r = &json["robot_servo"];
        assert_eq!(r["commands"], 100);
        assert_eq!(r["late_by_cycles"][0], 90);
        assert_eq!(r["late_by_cycles"][3], 7);
        assert_eq!(r["late_by_cycles"][SERVO_LATE_BINS - 1], 3);
        assert_eq!(
            (&r["extrapolated_cycles"], &r["held_cycles"], &r["holds"]),
            (&40.into(), &12.into(), &2.into())
        );
        assert_eq!(r["early_cycles"], 5);
        m.set_emulator_clock(ClockStats {
            cycles_elapsed: 1000,
            cycles_run: 990,
            cycles_late: 12,
            cycles_dropped: 4,
            cycles_paused: 0,
            max_behind_cycles: 41,
            cycles_behind: 6,
            cycles_slewed: 300,
            bursts: 3,
            holds_in_bursts: 1,
            cycles_waited: 77,
            waits: 9,
            waits_timed_out: 2,
        });
        let json = serde_json::to_value(summary(&mut m)).unwrap();
        let c = &json["emulator_clock"];
        for (k, v) in [
            ("cycles_elapsed", 1000),
            ("cycles_run", 990),
            ("cycles_late", 12),
            ("cycles_dropped", 4),
            ("max_behind_cycles", 41),
            ("cycles_slewed", 300),
            ("bursts", 3),
            ("holds_in_bursts", 1),
            ("cycles_waited", 77),
            ("waits", 9),
            ("waits_timed_out", 2),
        ] {
            assert_eq!(c[k], v, "{k}: {c}");
        }
    }

    #[test]
    fn missed_cycles_and_latency_percentiles_from_a_known_sequence() {
        let mut m = MotionMetrics::new();
        for k in 0..100u32 {
            let missed = [0, 0, 2, 0, 1].get(k as usize).copied().unwrap_or(0);
            let latency = f64::from(k + 1) * 1e-6;
            m.on_cycle(f64::from(k) * H, &record(missed, Some(latency), 10.0));
        }
        let s = summary(&mut m);
        let c = &s.cycles;
        assert_eq!(c.records, 100);
        assert_eq!(
            (c.missed_total, c.cycles_with_missed, c.missed_max),
            (3, 2, 2)
        );
        let l = c.latency_us.clone().unwrap();
        assert_eq!(l.samples, 100);
        assert_eq!(l.p50, 50.118723);
        assert_eq!(l.p99, 100.0);
        assert_eq!(l.max, 100.0);
        assert!(c.wake_jitter_us.is_none());
        assert_eq!(
            (c.time_scale_min, c.time_scale_mean),
            (Some(1.0), Some(1.0))
        );
        // Without any record (a runtime that does not report), everything is 0 / null.
        let mut empty = MotionMetrics::new();
        let s = summary(&mut empty);
        assert_eq!(s.cycles.records, 0);
        assert!(s.cycles.latency_us.is_none() && s.jerk.overall.rms_rad_s3.is_none());
    }

    /// A small xorshift generator for the seeded sweeps (no proptest in this package).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn sweep_cases() -> u64 {
        std::env::var("HRC_ADAPT_SWEEP_CASES")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(200)
    }

    /// Property (seeded sweep): a histogram quantile is never below the exact nearest-rank
    /// quantile, and at most one bin ratio (10^(1/40)) above it, or the maximum.
    #[test]
    fn histogram_quantiles_bound_the_exact_ones_within_one_bin() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        for _ in 0..sweep_cases() {
            let n = 1 + (rng.next() * 300.0) as usize;
            let mut xs: Vec<f64> = (0..n)
                .map(|_| 10f64.powf(-6.0 + 5.7 * rng.next()))
                .collect();
            let mut h = LogHistogram::default();
            for &x in &xs {
                h.add(x);
            }
            xs.sort_by(f64::total_cmp);
            for p in [0.5, 0.99] {
                let rank = ((p * n as f64).ceil() as usize).clamp(1, n);
                let exact = xs[rank - 1];
                let got = h.quantile_s(p).unwrap();
                let ratio = 10f64.powf(1.0 / BINS_PER_DECADE as f64);
                assert!(got >= exact * (1.0 - 1e-12), "p{p}: {got} < {exact}");
                assert!(
                    got <= exact * ratio * (1.0 + 1e-12),
                    "p{p}: {got} ≫ {exact}"
                );
                assert!(got <= xs[n - 1]);
            }
            assert_eq!(h.max_s(), Some(xs[n - 1]));
        }
    }

    /// Property (seeded sweep): on random signals with random stops, every "outside stops"
    /// count is at most the overall one, RMS ≤ max, a linear velocity has no jerk, and the
    /// window time is at most the trial time.
    #[test]
    fn outside_stop_figures_never_exceed_the_overall_ones() {
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        for _ in 0..sweep_cases().min(50) {
            let mut m = MotionMetrics::new();
            let mut lin = MotionMetrics::new();
            let slope = rng.next() - 0.5;
            let mut ts = 0.0;
            let n = 500 + (rng.next() * 1500.0) as u32;
            for k in 0..n {
                let t = f64::from(k) * H;
                ts += H * (1.0 + (rng.next() * 4.0).floor());
                let qd = [(); DOF].map(|()| 0.2 * (rng.next() - 0.5));
                m.on_state(t, &state(ts, qd, 0.3 * rng.next()));
                lin.on_state(t, &state(ts, [slope * ts; DOF], 0.0));
                let verdict = if rng.next() < 0.005 {
                    stopped_007()
                } else {
                    Verdict::Passed
                };
                m.on_verdict(t, &verdict);
                m.on_cycle(t, &record(0, None, 5.0));
            }
            let s = summary(&mut m);
            assert!(s.velocity_reversals.outside_stops.total <= s.velocity_reversals.overall.total);
            assert!(s.stop_and_go.outside_stops <= s.stop_and_go.overall);
            assert!(s.jerk.outside_stops.samples <= s.jerk.overall.samples);
            assert!(s.jerk_limit.outside_stops.exceeding <= s.jerk_limit.overall.exceeding);
            let j = &s.jerk.overall;
            assert!(j.rms_rad_s3.unwrap() <= j.max_rad_s3.unwrap());
            assert!(s.stop_windows.time_s <= f64::from(n) * H + 1e-9);
            let l = summary(&mut lin);
            assert!(
                l.jerk.overall.max_rad_s3.unwrap() < 1e-6,
                "{:?}",
                l.jerk.overall
            );
        }
    }
}
