//! `config/trial.toml`: what a trial loads and the workspace → robot base transform.

use std::path::{Path, PathBuf};
use std::time::Duration;

use robot_io::realtime::RtPriority;
use serde::{Deserialize, Serialize};

use crate::Error;

/// Highest `cue_rate_hz` [Hz]: the fastest camera mode the front-end runs (and 4× the
/// assessment's 30 Hz design rate).
pub(crate) const MAX_CUE_RATE_HZ: f64 = 120.0;
/// Longest `max_duration_s` [s]: one hour, six times the shipped 600 s; it bounds the trial's
/// cycle count and log size.
pub(crate) const MAX_DURATION_S: f64 = 3600.0;
/// Longest `lead_time_s` [s]: 600 s, the shipped trial's whole length.
pub(crate) const MAX_LEAD_TIME_S: f64 = 600.0;

/// The trial configuration file (every key is documented in `config/trial.toml`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrialConfig {
    /// Workspace calibration file (relative to the config file once loaded: absolute here).
    pub workspace: PathBuf,
    /// Controller file (`adapt::controller::RawHandoverFile`).
    pub controller: PathBuf,
    /// Adaptive policy rule table.
    pub policy_table: PathBuf,
    /// Assessment model constants; `None` for the defaults.
    #[serde(default)]
    pub assess: Option<PathBuf>,
    /// Cue and assessment rate [Hz].
    pub cue_rate_hz: f64,
    /// Longest simulated trial [s].
    pub max_duration_s: f64,
    /// The robot starts fetching part k this long before the operator's nominal need [s].
    pub lead_time_s: f64,
    /// When the policy holds the approach until the operator is ready (a start gate), the robot
    /// fetches this much earlier still and waits with the part at the staging pose [s]; 0
    /// without the key.
    #[serde(default)]
    pub staged_lead_s: f64,
    /// Log every 500 Hz robot state (and separation sample) instead of decimating to 100 Hz.
    #[serde(default)]
    pub robot_full_rate: bool,
    /// Workspace → base transform.
    pub frame: FrameConfig,
    /// What happens when the robot link is lost (`[link]`; defaults without the table).
    #[serde(default)]
    pub link: LinkConfig,
    /// When a task counts as impossible (`[progress]`; defaults without the table).
    #[serde(default)]
    pub progress: ProgressConfig,
    /// Real-time scheduling of the threads a control cycle waits on (`[realtime]`; defaults
    /// without the table).
    #[serde(default)]
    pub realtime: RealtimeConfig,
    /// The in-process emulator (`--robot emulator`; `[emulator]`; defaults without the table).
    #[serde(default)]
    pub emulator: EmulatorSection,
    /// The simulated operator (`[operator]`; defaults without the table).
    #[serde(default)]
    pub operator: OperatorSection,
}

/// `[operator]`: the **simulated** operator ([`crate::trial::operator::SimulatedOperator`]).
/// Simulation only: a trial whose cues come from a camera (`--cues camera`) or a recorded file
/// (`--cues <file>`) has no simulated operator and ignores it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OperatorSection {
    /// `[operator.response]`: how the simulated operator responds to the robot.
    pub response: OperatorResponse,
}

/// `[operator.response]`: the simulated operator's response to the robot, its effect sizes.
///
/// **ASSUMPTION, every field.** The paper gives no hesitation statistics and the bundled KTH
/// recording has no robot giver, so none of these is measured
/// (`docs/calibration/operator_fit.md`). They encode the hypothesis the A/B experiment tests
/// the adaptive policy against: an operator hesitates more when the approach is fast or jerky,
/// or when a part arrives while their attention is elsewhere. The defaults are the constants
/// the simulated operator had before they were made configurable (so results did not change);
/// `hrc-adapt experiment --sensitivity` shows how the A/B result depends on them.
///
/// During a collaboration period with the handover pending, with `v` the TCP speed [m/s] and
/// `a` its peak acceleration over the last cue interval [m/s²]:
/// - stress `s = k_speed·v/ref_speed_m_s + k_acc·a/ref_acc_m_s2` [-];
/// - hesitations start at the level's base rate × `(1 + s)` [1/s];
/// - their median duration is the level's × `(1 + k_duration·s)` [s];
/// - when the robot starts presenting while the operator's attention is elsewhere (assembling,
///   or away at the storage or instruction area), a hesitation starts with probability
///   `surprise_p`, its stress raised by `surprise_stress`.
///
/// All zero gains (`k_speed = k_acc = surprise_p = 0`) leave only the base rate: an operator
/// who does not respond to the robot at all.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct OperatorResponse {
    /// Reference TCP speed of the stress term [m/s], > 0. Assumption: 0.25 m/s, the
    /// collaborative TCP speed cap, so the cap itself adds `k_speed` of stress.
    pub ref_speed_m_s: f64,
    /// Reference TCP acceleration of the stress term [m/s²], > 0. Assumption: 1.0 m/s².
    pub ref_acc_m_s2: f64,
    /// Stress per reference speed [-], ≥ 0. Assumption: 1.5 (a fast approach weighs more than
    /// a jerky one).
    pub k_speed: f64,
    /// Stress per reference acceleration [-], ≥ 0. Assumption: 1.0.
    pub k_acc: f64,
    /// Relative lengthening of a hesitation per unit of stress [-], ≥ 0. Assumption: 0.5 (a
    /// stressed operator's hesitation lasts longer, less than in proportion).
    pub k_duration: f64,
    /// Probability of a hesitation when the robot starts presenting while the operator's
    /// attention is elsewhere [-], in [0, 1]. Assumption: 0.5.
    pub surprise_p: f64,
    /// Stress such a surprise adds to the hesitation's duration [-], ≥ 0. Assumption: 1.0.
    pub surprise_stress: f64,
}

impl Default for OperatorResponse {
    fn default() -> Self {
        Self {
            ref_speed_m_s: 0.25,
            ref_acc_m_s2: 1.0,
            k_speed: 1.5,
            k_acc: 1.0,
            k_duration: 0.5,
            surprise_p: 0.5,
            surprise_stress: 1.0,
        }
    }
}

impl OperatorResponse {
    /// The fields with their names, in file order.
    pub(crate) fn fields(&self) -> [(&'static str, f64); 7] {
        [
            ("ref_speed_m_s", self.ref_speed_m_s),
            ("ref_acc_m_s2", self.ref_acc_m_s2),
            ("k_speed", self.k_speed),
            ("k_acc", self.k_acc),
            ("k_duration", self.k_duration),
            ("surprise_p", self.surprise_p),
            ("surprise_stress", self.surprise_stress),
        ]
    }

    /// Refuses a value out of its range (see the field docs); the error names `prefix` + the
    /// field (`operator.response.k_speed`) and the value.
    pub(crate) fn validate(&self, prefix: &str) -> crate::Result<()> {
        for (key, v) in self.fields() {
            let (ok, rule) = match key {
                "ref_speed_m_s" | "ref_acc_m_s2" => {
                    (v.is_finite() && v > 0.0, "must be finite and > 0")
                }
                "surprise_p" => ((0.0..=1.0).contains(&v), "must be a probability in [0, 1]"),
                _ => (v.is_finite() && v >= 0.0, "must be finite and >= 0"),
            };
            ensure!(
                ok,
                Error::config(format!("{prefix}{key}"), format!("{rule}, got {v}"))
            );
        }
        Ok(())
    }
}

/// `[emulator]`: the in-process emulator of `--robot emulator`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EmulatorSection {
    /// At `--speedup` > 1, how long the emulator's clock waits for a late servo command
    /// before it runs on as a controller would [ms of wall time], in [0, 1000]; 0: never waits
    /// (`robot_io::emulator::ClientWait`). At speedup 1 it never waits, whatever this says.
    pub wait_for_client_ms: f64,
}

impl Default for EmulatorSection {
    fn default() -> Self {
        Self {
            wait_for_client_ms: 20.0,
        }
    }
}

impl EmulatorSection {
    /// The wait for a clock at `speedup` (`None`: never waits).
    pub(crate) fn wait_for_client(self, speedup: u32) -> Option<Duration> {
        (speedup > 1 && self.wait_for_client_ms > 0.0)
            .then(|| Duration::from_secs_f64(self.wait_for_client_ms / 1e3))
    }
}

/// `[realtime]`: `SCHED_FIFO` priorities [-] of the threads a 2 ms control cycle waits on
/// (`robot_io::realtime`), each in [1, 99], 0 for normal scheduling. RTDE robots only (the
/// emulator or a UR5e); `--robot sim` runs on a mock clock and changes no thread.
///
/// Off by default (every priority 0), as in ur_rtde, whose interfaces change a thread's
/// scheduling only when a priority is given. Its real-time examples use receive 90 and
/// control 85; `config/trial.toml` names those for a lab PC driving a UR5e at speedup 1. The
/// cue cycle (assessment and policy) stays at normal priority: with the in-process emulator at
/// speedup 10 on a 2-core machine, run as root, the three real-time threads kept it from
/// running for most of a short trial (seen when fe222c6 had them on by default: CI's link-loss
/// tests of `runtime_exit_tests.rs` failed because their trials ended before the cue cycle had
/// reported 1 s of trial time; with the priorities at 0 they pass).
/// Refused by the OS (no `CAP_SYS_NICE`, `RLIMIT_RTPRIO` too low), a thread runs at normal
/// priority, a warning says so and `summary.json`'s `motion.scheduling` records it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RealtimeConfig {
    /// The control thread (read → controller → supervisor → send) [-].
    pub control_priority: u8,
    /// The RTDE client's I/O threads (receive samples, write commands), and the in-process
    /// emulator's servers, which share them [-].
    pub rtde_io_priority: u8,
    /// The in-process emulator's clock thread [-].
    pub emulator_clock_priority: u8,
}

impl RealtimeConfig {
    /// Refuses a priority outside 0 and [1, 99], naming its key.
    fn validate(self) -> crate::Result<()> {
        for (key, p) in [
            ("realtime.control_priority", self.control_priority),
            ("realtime.rtde_io_priority", self.rtde_io_priority),
            (
                "realtime.emulator_clock_priority",
                self.emulator_clock_priority,
            ),
        ] {
            ensure!(
                p == 0 || RtPriority::new(p).is_ok(),
                Error::config(
                    key,
                    format!("must be 0 (normal scheduling) or in [1, 99], got {p}")
                )
            );
        }
        Ok(())
    }

    /// The control thread's priority (`None`: normal scheduling).
    pub(crate) fn control(self) -> Option<RtPriority> {
        RtPriority::new(self.control_priority).ok()
    }

    /// The RTDE I/O threads' priority (`None`: normal scheduling).
    pub(crate) fn rtde_io(self) -> Option<RtPriority> {
        RtPriority::new(self.rtde_io_priority).ok()
    }

    /// The emulator clock's priority (`None`: normal scheduling).
    pub(crate) fn emulator_clock(self) -> Option<RtPriority> {
        RtPriority::new(self.emulator_clock_priority).ok()
    }
}

/// `[link]`: a lost robot link (RTDE robots only; see `runtime.rs`, "Link loss").
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinkConfig {
    /// No new robot state for this long (wall time) is a link loss [s], in [0.01, 60]. The
    /// supervisor has stopped the robot long before (SAF-REQ-009, after 3 missed cycles).
    pub lost_after_s: f64,
    /// Resume the trial once the link is back (else it ends as `link_lost`).
    pub resume: bool,
    /// With `resume`: end as `link_lost` if the link is not back this long after the loss
    /// (wall time) [s], in (0, 3600].
    pub resume_within_s: f64,
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            lost_after_s: 1.0,
            resume: false,
            resume_within_s: 10.0,
        }
    }
}

/// `[progress]`: when a task counts as impossible.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ProgressConfig {
    /// A motion phase (fetch, approach, retreat) that gets no closer to its target for this
    /// long (trial time) ends the trial as `task_impossible` [s], in [0.1, 3600].
    pub stuck_after_s: f64,
}

impl Default for ProgressConfig {
    fn default() -> Self {
        Self {
            stuck_after_s: 10.0,
        }
    }
}

/// The robot base pose in the workspace frame.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameConfig {
    /// Base origin in the workspace frame [m].
    pub robot_base_origin_m: [f64; 3],
    /// Yaw of the base axes about z, relative to the workspace axes [deg].
    pub robot_base_yaw_deg: f64,
}

impl FrameConfig {
    /// A workspace-frame point [m] in the base frame [m].
    pub(crate) fn to_base(self, p: [f64; 3]) -> [f64; 3] {
        let o = self.robot_base_origin_m;
        let (s, c) = self.robot_base_yaw_deg.to_radians().sin_cos();
        let (dx, dy, dz) = (p[0] - o[0], p[1] - o[1], p[2] - o[2]);
        [c * dx + s * dy, -s * dx + c * dy, dz]
    }

    /// A workspace-frame direction [-] in the base frame (rotation only).
    pub(crate) fn direction_to_base(self, d: [f64; 3]) -> [f64; 3] {
        let (s, c) = self.robot_base_yaw_deg.to_radians().sin_cos();
        [c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]]
    }

    /// A base-frame point [m] in the workspace frame [m].
    pub(crate) fn to_workspace(self, p: [f64; 3]) -> [f64; 3] {
        let o = self.robot_base_origin_m;
        let (s, c) = self.robot_base_yaw_deg.to_radians().sin_cos();
        [
            o[0] + c * p[0] - s * p[1],
            o[1] + s * p[0] + c * p[1],
            o[2] + p[2],
        ]
    }
}

/// The shipped `config/trial.toml`, embedded (its relative paths resolve against `config/`).
pub const SHIPPED_TOML: &str = include_str!("../../config/trial.toml");

impl TrialConfig {
    /// Parses `text`; relative paths are resolved against `base_dir`.
    pub fn from_toml_str(text: &str, base_dir: &Path) -> crate::Result<TrialConfig> {
        let mut cfg: TrialConfig = toml::from_str(text).map_err(Error::toml("the trial config"))?;
        for p in [
            &mut cfg.workspace,
            &mut cfg.controller,
            &mut cfg.policy_table,
        ] {
            *p = base_dir.join(&*p);
        }
        if let Some(a) = cfg.assess.as_mut() {
            *a = base_dir.join(&*a);
        }
        ensure!(
            cfg.cue_rate_hz > 0.0 && cfg.cue_rate_hz <= MAX_CUE_RATE_HZ,
            Error::config(
                "cue_rate_hz",
                format!(
                    "must be in (0, {MAX_CUE_RATE_HZ}] Hz, got {}",
                    cfg.cue_rate_hz
                )
            )
        );
        ensure!(
            cfg.max_duration_s > 0.0 && cfg.max_duration_s <= MAX_DURATION_S,
            Error::config(
                "max_duration_s",
                format!(
                    "must be in (0, {MAX_DURATION_S}] s, got {}",
                    cfg.max_duration_s
                )
            )
        );
        ensure!(
            (0.0..=MAX_LEAD_TIME_S).contains(&cfg.lead_time_s),
            Error::config(
                "lead_time_s",
                format!(
                    "must be in [0, {MAX_LEAD_TIME_S}] s, got {}",
                    cfg.lead_time_s
                )
            )
        );
        ensure!(
            (0.0..=MAX_LEAD_TIME_S).contains(&cfg.staged_lead_s),
            Error::config(
                "staged_lead_s",
                format!(
                    "must be in [0, {MAX_LEAD_TIME_S}] s, got {}",
                    cfg.staged_lead_s
                )
            )
        );
        ensure!(
            cfg.frame.robot_base_origin_m.iter().all(|v| v.is_finite())
                && cfg.frame.robot_base_yaw_deg.is_finite(),
            Error::config("frame", "values must be finite")
        );
        let link = cfg.link;
        ensure!(
            (0.01..=60.0).contains(&link.lost_after_s),
            Error::config(
                "link.lost_after_s",
                format!("must be in [0.01, 60] s, got {}", link.lost_after_s)
            )
        );
        ensure!(
            link.resume_within_s > 0.0 && link.resume_within_s <= 3600.0,
            Error::config(
                "link.resume_within_s",
                format!("must be in (0, 3600] s, got {}", link.resume_within_s)
            )
        );
        ensure!(
            (0.1..=3600.0).contains(&cfg.progress.stuck_after_s),
            Error::config(
                "progress.stuck_after_s",
                format!(
                    "must be in [0.1, 3600] s, got {}",
                    cfg.progress.stuck_after_s
                )
            )
        );
        cfg.realtime.validate()?;
        let wait = cfg.emulator.wait_for_client_ms;
        ensure!(
            (0.0..=1000.0).contains(&wait),
            Error::config(
                "emulator.wait_for_client_ms",
                format!("must be in [0, 1000] ms, got {wait}")
            )
        );
        cfg.operator.response.validate("operator.response.")?;
        Ok(cfg)
    }

    /// Reads a config file.
    pub fn from_file(path: &Path) -> crate::Result<TrialConfig> {
        let text = std::fs::read_to_string(path).map_err(Error::io("read", path))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        Self::from_toml_str(&text, dir).map_err(|e| e.in_file(path))
    }

    /// The shipped config, with paths under this repository's `config/`.
    pub fn shipped() -> crate::Result<TrialConfig> {
        Self::from_toml_str(
            SHIPPED_TOML,
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("config"),
        )
    }
}

/// Refuses a handover task whose home, pick or handover pose (joint space, after IK) puts the
/// TCP, the wrist or the elbow outside the safety supervisor's workspace box `workspace`
/// (SAF-REQ-006, [`safety::WorkspaceBox`]). Such a task could never be done: every command
/// towards the pose would be stopped (issue 10: a pick pose below the table ran 600 s with
/// 272,161 SAF-REQ-006 stops). The error names `file`, the pose, the point and where it is.
/// The check is here, in the binary, so that `adapt` does not depend on `safety`.
pub(crate) fn check_task_poses(
    task: &adapt::task::TaskConfig,
    workspace: &safety::WorkspaceBox,
    file: &Path,
) -> crate::Result<()> {
    for (pose, q) in [
        ("poses.home", &task.home_q_rad),
        ("poses.pick", &task.pick_q_rad),
        ("poses.handover", &task.handover_q_rad),
    ] {
        for (point, p) in safety::points::arm_points(q).as_array() {
            let name = match point {
                safety::points::ArmPoint::Tcp => "TCP",
                safety::points::ArmPoint::Wrist => "wrist",
                safety::points::ArmPoint::Elbow => "elbow",
            };
            let (lo, hi) = (workspace.min_m(), workspace.max_m());
            ensure!(
                workspace.contains(&p),
                Error::config(
                    pose,
                    format!(
                        "puts the {name} at ({:.3}, {:.3}, {:.3}) m (base frame), outside the \
                         safety supervisor's workspace box [{}, {}] × [{}, {}] × [{}, {}] m \
                         (SAF-REQ-006): every motion to it would be stopped",
                        p[0], p[1], p[2], lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]
                    )
                )
                .in_file(file)
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_config_parses_and_maps_the_handover_pose_into_the_collaboration_area() {
        let cfg = TrialConfig::shipped().unwrap();
        let p = cfg.frame.to_workspace([-0.73, -0.13, 0.24]);
        assert!((p[0] - 0.90).abs() < 1e-9 && (p[1] - 0.60).abs() < 1e-9);
        let back = cfg.frame.to_base(p);
        assert!((back[0] + 0.73).abs() < 1e-12 && (back[2] - 0.24).abs() < 1e-12);
        let rotated = FrameConfig {
            robot_base_origin_m: [1.0, 2.0, 0.5],
            robot_base_yaw_deg: 37.0,
        };
        let q = rotated.to_base(rotated.to_workspace([0.3, -0.2, 0.1]));
        assert!((q[0] - 0.3).abs() < 1e-12 && (q[1] + 0.2).abs() < 1e-12);
    }

    /// The shipped config with `key = value` in place of its line for `key`.
    fn with(key: &str, value: &str) -> crate::Result<TrialConfig> {
        let line = SHIPPED_TOML
            .lines()
            .find(|l| l.starts_with(&format!("{key} = ")))
            .unwrap_or_else(|| panic!("{key} is in the shipped config"));
        TrialConfig::from_toml_str(
            &SHIPPED_TOML.replace(line, &format!("{key} = {value}")),
            Path::new("/cfg"),
        )
    }

    #[test]
    fn durations_are_bounded_and_the_error_names_the_key() {
        // At the bounds: accepted.
        assert!(with("max_duration_s", "3600.0").is_ok());
        assert!(with("lead_time_s", "600.0").is_ok());
        assert!(with("staged_lead_s", "600.0").is_ok());
        assert!(with("wait_for_client_ms", "1000.0").is_ok());
        let never = with("wait_for_client_ms", "0.0").unwrap().emulator;
        assert_eq!(never.wait_for_client(4), None, "0: the clock never waits");
        let shipped = TrialConfig::shipped().unwrap().emulator;
        assert_eq!(
            shipped,
            EmulatorSection::default(),
            "the file states the default"
        );
        assert_eq!(shipped.wait_for_client(4), Some(Duration::from_millis(20)));
        assert_eq!(
            shipped.wait_for_client(1),
            None,
            "a real-time clock never waits"
        );
        // Past them (1e20 passed validation at a077dd5): refused, naming the key and bound.
        for (key, bad, bound) in [
            ("max_duration_s", "3600.5", "3600"),
            ("max_duration_s", "1e20", "3600"),
            ("max_duration_s", "nan", "3600"),
            ("lead_time_s", "600.5", "600"),
            ("lead_time_s", "1e20", "600"),
            ("staged_lead_s", "600.5", "600"),
            ("staged_lead_s", "-1.0", "600"),
            ("cue_rate_hz", "1e20", "120"),
            ("wait_for_client_ms", "1000.5", "1000"),
            ("wait_for_client_ms", "-1.0", "[0, 1000]"),
            ("wait_for_client_ms", "nan", "1000"),
        ] {
            let e = with(key, bad).unwrap_err().with_causes().to_string();
            assert!(e.contains(key) && e.contains(bound), "{key} = {bad}: {e}");
        }
    }

    #[test]
    fn realtime_priorities_are_0_or_1_to_99_and_the_error_names_the_key() {
        let shipped = TrialConfig::shipped().unwrap().realtime;
        assert_eq!(
            shipped,
            RealtimeConfig::default(),
            "the file states the defaults"
        );
        // Off unless asked for (ur_rtde's default too).
        assert_eq!(
            (
                shipped.control(),
                shipped.rtde_io(),
                shipped.emulator_clock()
            ),
            (None, None, None)
        );
        for key in [
            "control_priority",
            "rtde_io_priority",
            "emulator_clock_priority",
        ] {
            // A priority for that thread alone; the others stay at normal scheduling.
            let on = with(key, "85").unwrap().realtime;
            let got =
                [on.control(), on.rtde_io(), on.emulator_clock()].map(|p| p.map(RtPriority::get));
            let want = match key {
                "control_priority" => [Some(85), None, None],
                "rtde_io_priority" => [None, Some(85), None],
                _ => [None, None, Some(85)],
            };
            assert_eq!(got, want, "{key} = 85: {on:?}");
            assert!(with(key, "99").is_ok());
            let e = with(key, "100").unwrap_err().with_causes().to_string();
            assert!(
                e.contains(&format!("realtime.{key}")) && e.contains("[1, 99]"),
                "{e}"
            );
            // Negative or fractional values are no u8: refused by the parser, naming the key.
            let e = with(key, "-1").unwrap_err().with_causes().to_string();
            assert!(e.contains(key), "{e}");
        }
    }

    /// The response defaults are the constants the simulated operator had before they became
    /// configurable (src/trial/operator.rs `COMMON` at 7d008ab: 0.25 m/s, 1.0 m/s², 1.5, 1.0,
    /// the duration factor 0.5, 0.5, 1.0), and the shipped file states them.
    #[test]
    fn operator_response_defaults_are_the_old_constants_and_the_shipped_values() {
        let d = OperatorResponse::default();
        assert_eq!(
            d,
            OperatorResponse {
                ref_speed_m_s: 0.25,
                ref_acc_m_s2: 1.0,
                k_speed: 1.5,
                k_acc: 1.0,
                k_duration: 0.5,
                surprise_p: 0.5,
                surprise_stress: 1.0,
            }
        );
        assert_eq!(TrialConfig::shipped().unwrap().operator.response, d);
        // Without the table: the defaults.
        let start = SHIPPED_TOML.find("[operator.response]").unwrap();
        let end = start + SHIPPED_TOML[start..].find("\n\n").unwrap();
        let without = format!("{}{}", &SHIPPED_TOML[..start], &SHIPPED_TOML[end..]);
        assert!(!without.contains("k_speed = "));
        let cfg = TrialConfig::from_toml_str(&without, Path::new("/cfg")).unwrap();
        assert_eq!(cfg.operator, OperatorSection::default());
        // One key given, the others default.
        let one = with("k_speed", "0.0").unwrap().operator.response;
        assert_eq!(one, OperatorResponse { k_speed: 0.0, ..d });
    }

    #[test]
    fn operator_response_values_out_of_range_and_unknown_keys_are_refused_by_name() {
        for (key, ok) in [
            ("k_speed", "0.0"),
            ("surprise_p", "1.0"),
            ("surprise_p", "0.0"),
            ("ref_speed_m_s", "1e-3"),
        ] {
            assert!(with(key, ok).is_ok(), "{key} = {ok}");
        }
        for (key, bad, rule) in [
            ("ref_speed_m_s", "0.0", "> 0, got 0"),
            ("ref_speed_m_s", "-0.25", "> 0, got -0.25"),
            ("ref_acc_m_s2", "inf", "> 0, got inf"),
            ("k_speed", "-1.5", ">= 0, got -1.5"),
            ("k_speed", "nan", ">= 0, got NaN"),
            ("k_acc", "inf", ">= 0, got inf"),
            ("k_duration", "-0.5", ">= 0, got -0.5"),
            ("surprise_p", "1.5", "[0, 1], got 1.5"),
            ("surprise_p", "-0.1", "[0, 1], got -0.1"),
            ("surprise_p", "nan", "[0, 1], got NaN"),
            ("surprise_stress", "-1.0", ">= 0, got -1"),
        ] {
            let e = with(key, bad).unwrap_err().with_causes().to_string();
            assert!(
                e.contains(&format!("`operator.response.{key}`")) && e.contains(rule),
                "{key} = {bad}: {e}"
            );
        }
        // An unknown key in the table, or in [operator], is refused by name.
        for (from, to) in [
            ("k_speed = ", "k_sped = "),
            (
                "[operator.response]",
                "[operator]\nmood = 1.0\n[operator.response]",
            ),
        ] {
            let text = SHIPPED_TOML.replacen(from, to, 1);
            let e = TrialConfig::from_toml_str(&text, Path::new("/cfg"))
                .unwrap_err()
                .with_causes()
                .to_string();
            let key = if from == "k_speed = " {
                "k_sped"
            } else {
                "mood"
            };
            assert!(e.contains(key) && e.contains("unknown field"), "{e}");
        }
    }

    /// The shipped controller file with the pick pose's flange height set to `z_m` [m].
    fn controller_with_pick_z(dir: &Path, z_m: f64) -> PathBuf {
        let shipped = TrialConfig::shipped().unwrap().controller;
        let mut v: toml::Value =
            toml::from_str(&std::fs::read_to_string(shipped).unwrap()).unwrap();
        v["controller"]["task"]["poses"]["pick"]["position_m"][2] = toml::Value::Float(z_m);
        let path = dir.join("handover.toml");
        std::fs::write(&path, toml::to_string(&v).unwrap()).unwrap();
        path
    }

    #[test]
    fn saf_req_006_a_task_pose_outside_the_workspace_box_is_refused_at_load() {
        // Issue 10: a pick pose below the table ran 600 s with 272,161 SAF-REQ-006 stops and
        // exited 0. It is refused before the trial starts, naming the pose and the point.
        let tmp = tempfile::tempdir().unwrap();
        let mut spec = crate::trial::runtime::test_spec(crate::trial::operator::Level::L1, 1, 2.0);
        spec.config.controller = controller_with_pick_z(tmp.path(), -0.05);
        let out = tmp.path().join("run");
        let e = crate::trial::run_simulated(&spec, &out, false)
            .unwrap_err()
            .with_causes()
            .to_string();
        assert!(
            e.contains("poses.pick") && e.contains("TCP") && e.contains("workspace box"),
            "{e}"
        );
        assert!(
            !out.join("summary.json").exists(),
            "the trial did not start"
        );
        assert!(e.contains("(-0.380, 0.350, -0.050) m"), "{e}");
        // The shipped task and the example task are inside the box.
        let box_ = safety::SupervisorConfig::ur5e().workspace;
        let file = Path::new("handover.toml");
        let mut task = adapt::task::TaskConfig::example();
        assert!(check_task_poses(&task, &box_, file).is_ok());
        // Upper arm horizontal (shoulder 0), forearm hanging down (elbow π/2): by UR5e DH
        // (d1 = 0.1625 m, a3 = −0.3922 m) the wrist is at z = 0.1625 − 0.3922 = −0.23 m,
        // below the box's 0.02 m floor; the elbow stays at 0.1625 m, inside.
        task.handover_q_rad = [0.0, 0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0];
        let wrist = safety::points::arm_points(&task.handover_q_rad).wrist;
        assert!((wrist[2] + 0.2297).abs() < 1e-3, "{wrist:?}");
        let e = check_task_poses(&task, &box_, file)
            .unwrap_err()
            .with_causes()
            .to_string();
        assert!(
            e.contains("`poses.handover`") && e.contains("handover.toml"),
            "{e}"
        );
    }
}
