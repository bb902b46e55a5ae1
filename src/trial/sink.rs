//! Where the runtime sends a trial's streams: the [`TrialSink`] trait, and [`MinimalLog`], a
//! small deterministic writer of `indicators.csv`, `robot.csv` and `summary.json` used until
//! the full `TrialLog` (`log.rs`: MCAP, report) is wired in behind the same trait.
//!
//! Everything is written with fixed formatting and no wall-clock value, so a simulated trial's
//! files are byte-identical for the same seed and config.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use assess::{Assessment, CueFrame, Workspace};
use policies::Adaptation;
use robot_io::{JointCommand, RobotState};
use safety::Verdict;

use super::events::TrialEvent;

/// Receives a trial's streams. Times are trial time [s].
pub(crate) trait TrialSink {
    /// One cue frame (simulated operator: labelled as simulation by the log's metadata).
    fn cues(&mut self, frame: &CueFrame);
    /// One assessment (cue rate).
    fn assessment(&mut self, a: &Assessment, workspace: &Workspace);
    /// The policy's output for this assessment.
    fn adaptation(&mut self, t: f64, a: &Adaptation);
    /// One robot state (500 Hz; the sink decimates).
    fn robot_state(&mut self, t: f64, s: &RobotState);
    /// One command and the supervisor's verdict (500 Hz).
    fn command(&mut self, t: f64, cmd: &JointCommand, verdict: &Verdict);
    /// A trial event.
    fn event(&mut self, t: f64, e: &TrialEvent);
    /// Flush and close; returns the trial folder.
    fn finish(self: Box<Self>) -> anyhow::Result<PathBuf>;
}

/// Metadata of a trial, written into `summary.json`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TrialMeta {
    /// Participant id.
    pub(crate) participant: String,
    /// `L1`, `L2` or `L3`.
    pub(crate) condition: String,
    /// `adaptive` or `fixed`.
    pub(crate) policy: String,
    /// Seed of the simulated operator.
    pub(crate) seed: u64,
    /// `simulated_operator` (or a recorded / live source).
    pub(crate) cue_source: String,
    /// `sim`, `emulator` or the robot's address.
    pub(crate) robot: String,
}

/// The minimal deterministic log (see the module docs).
#[derive(Debug)]
pub(crate) struct MinimalLog {
    dir: PathBuf,
    meta: TrialMeta,
    indicators: String,
    robot: String,
    robot_every: u64,
    robot_count: u64,
    last_t: f64,
    cwl_sum: f64,
    cwl_max: f64,
    cwl_n: u64,
    dominant_s: [f64; 6],
    last_dominant: Option<usize>,
    last_assess_t: Option<f64>,
    need: Vec<(u32, f64)>,
    presented: Vec<(u32, f64)>,
    handovers: Vec<serde_json::Value>,
    idle_since: Option<f64>,
    idle_s: f64,
    hes_since: Option<f64>,
    hes_s: f64,
    adaptation_changes: u64,
    safety_events: Vec<serde_json::Value>,
    returned: u64,
    finish_reason: &'static str,
}

impl MinimalLog {
    /// Creates `dir` and the log; `robot_log_rate_hz` decimates the 500 Hz robot state.
    pub(crate) fn create(
        dir: &Path,
        meta: TrialMeta,
        robot_log_rate_hz: f64,
    ) -> anyhow::Result<MinimalLog> {
        std::fs::create_dir_all(dir)?;
        let mut indicators = String::with_capacity(1 << 20);
        indicators.push_str(
            "t_s,valid,confirmed,aed,tid,icd,col,abi,asd_ctx,ohd,hrc_cwl,category,dominant,hesitating\n",
        );
        let mut robot = String::with_capacity(1 << 20);
        robot.push_str("t_s,q0,q1,q2,q3,q4,q5,tcp_x,tcp_y,tcp_z,tcp_speed_m_s,speed_scaling\n");
        Ok(MinimalLog {
            dir: dir.to_owned(),
            meta,
            indicators,
            robot,
            robot_every: (500.0 / robot_log_rate_hz).round().max(1.0) as u64,
            robot_count: 0,
            last_t: 0.0,
            cwl_sum: 0.0,
            cwl_max: 0.0,
            cwl_n: 0,
            dominant_s: [0.0; 6],
            last_dominant: None,
            last_assess_t: None,
            need: Vec::new(),
            presented: Vec::new(),
            handovers: Vec::new(),
            idle_since: None,
            idle_s: 0.0,
            hes_since: None,
            hes_s: 0.0,
            adaptation_changes: 0,
            safety_events: Vec::new(),
            returned: 0,
            finish_reason: "unknown",
        })
    }
}

const INDICATOR_KEYS: [&str; 6] = ["AED", "TID", "ICD", "ASD_ctx", "OHD", "none"];

impl TrialSink for MinimalLog {
    fn cues(&mut self, _frame: &CueFrame) {}

    fn assessment(&mut self, a: &Assessment, workspace: &Workspace) {
        let w = &a.windowed;
        let dom = a.dominant.indicator;
        let _ = writeln!(
            self.indicators,
            "{:.4},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{},{},{}",
            a.t,
            a.valid as u8,
            workspace.state_name(a.confirmed),
            w.aed,
            w.tid,
            w.icd,
            w.col,
            w.abi,
            w.asd_ctx,
            w.ohd,
            w.hrc_cwl,
            w.category.name(),
            policies::indicator_key(dom),
            a.hesitating as u8,
        );
        if let (Some(prev_t), Some(k)) = (self.last_assess_t, self.last_dominant) {
            self.dominant_s[k] += a.t - prev_t;
        }
        self.last_assess_t = Some(a.t);
        let key = policies::indicator_key(dom);
        self.last_dominant = INDICATOR_KEYS.iter().position(|k| *k == key);
        if w.hrc_cwl.is_finite() {
            self.cwl_sum += w.hrc_cwl;
            self.cwl_max = self.cwl_max.max(w.hrc_cwl);
            self.cwl_n += 1;
        }
        self.last_t = self.last_t.max(a.t);
    }

    fn adaptation(&mut self, _t: f64, _a: &Adaptation) {}

    fn robot_state(&mut self, t: f64, s: &RobotState) {
        if self.robot_count % self.robot_every == 0 {
            let v = &s.actual_tcp_speed;
            let q = &s.actual_q;
            let p = &s.actual_tcp_pose;
            let _ = writeln!(
                self.robot,
                "{t:.3},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.5},{:.5},{:.5},{:.5},{:.3}",
                q[0],
                q[1],
                q[2],
                q[3],
                q[4],
                q[5],
                p[0],
                p[1],
                p[2],
                (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(),
                s.speed_scaling
            );
        }
        self.robot_count += 1;
        self.last_t = self.last_t.max(t);
    }

    fn command(&mut self, _t: f64, _cmd: &JointCommand, _verdict: &Verdict) {}

    fn event(&mut self, t: f64, e: &TrialEvent) {
        match *e {
            TrialEvent::OperatorNeedsPart { handover } => self.need.push((handover, t)),
            TrialEvent::Presented { handover } => self.presented.push((handover, t)),
            TrialEvent::Grasped { handover } => {
                let need = self.need.iter().rev().find(|(h, _)| *h == handover);
                let pres = self.presented.iter().rev().find(|(h, _)| *h == handover);
                self.handovers.push(serde_json::json!({
                    "handover": handover,
                    "grasped_s": round3(t),
                    "operator_wait_s": need.map(|(_, n)| round3(t - n)),
                    "robot_wait_s": pres.map(|(_, p)| round3(t - p)),
                }));
            }
            TrialEvent::PartReturned { .. } => self.returned += 1,
            TrialEvent::OperatorIdle { idle: true } => self.idle_since = Some(t),
            TrialEvent::OperatorIdle { idle: false } => {
                if let Some(s) = self.idle_since.take() {
                    self.idle_s += t - s;
                }
            }
            TrialEvent::Hesitation { active: true } => self.hes_since = Some(t),
            TrialEvent::Hesitation { active: false } => {
                if let Some(s) = self.hes_since.take() {
                    self.hes_s += t - s;
                }
            }
            TrialEvent::AdaptationChanged { .. } => self.adaptation_changes += 1,
            TrialEvent::Safety {
                reaction,
                requirement,
            } => self.safety_events.push(serde_json::json!({
                "t_s": round3(t), "reaction": reaction, "requirement": requirement,
            })),
            TrialEvent::Finished { reason } => self.finish_reason = reason,
            TrialEvent::TaskPhase { .. } => {}
        }
        self.last_t = self.last_t.max(t);
    }

    fn finish(self: Box<Self>) -> anyhow::Result<PathBuf> {
        let dominant: serde_json::Map<String, serde_json::Value> = INDICATOR_KEYS
            .iter()
            .zip(self.dominant_s)
            .map(|(k, s)| ((*k).to_owned(), serde_json::json!(round3(s))))
            .collect();
        let summary = serde_json::json!({
            "simulation": self.meta.cue_source == "simulated_operator",
            "participant": self.meta.participant,
            "condition": self.meta.condition,
            "policy": self.meta.policy,
            "seed": self.meta.seed,
            "cue_source": self.meta.cue_source,
            "robot": self.meta.robot,
            "finish_reason": self.finish_reason,
            "completion_time_s": round3(self.last_t),
            "handovers": self.handovers,
            "parts_returned": self.returned,
            "operator_idle_s": round3(self.idle_s),
            "hesitation_share": if self.last_t > 0.0 { round3(self.hes_s / self.last_t) } else { 0.0 },
            "hrc_cwl_mean": if self.cwl_n > 0 { round3(self.cwl_sum / self.cwl_n as f64) } else { 0.0 },
            "hrc_cwl_max": round3(self.cwl_max),
            "dominant_time_s": dominant,
            "adaptation_changes": self.adaptation_changes,
            "safety_events": self.safety_events,
        });
        let write = |name: &str, bytes: &[u8]| -> anyhow::Result<()> {
            let mut f = std::fs::File::create(self.dir.join(name))?;
            f.write_all(bytes)?;
            Ok(())
        };
        write("indicators.csv", self.indicators.as_bytes())?;
        write("robot.csv", self.robot.as_bytes())?;
        let mut json = serde_json::to_string_pretty(&summary)?;
        json.push('\n');
        write("summary.json", json.as_bytes())?;
        Ok(self.dir)
    }
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}
