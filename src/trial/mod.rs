//! `hrc-adapt trial`: one closed-loop adaptive handover trial (issue 5).
//!
//! - [`operator`]: the **simulated operator** (seeded stochastic gearbox-task model), the
//!   default cue source;
//! - `cues`: the cue sources; `--cues <file.csv>` replays a **recorded cue file** by time
//!   (sample-and-hold, open loop: the recorded operator does not react to the robot);
//! - [`runtime`]: cues → assessor (30 Hz) → policy → controller (500 Hz) → supervisor → robot
//!   on a mock clock with `SimRobot` ([`runtime::run_simulated`], for the experiment runner
//!   and the determinism test) or on the controller's clock over RTDE;
//! - `backend`: the RTDE robots: the controller emulator in-process on loopback ports
//!   (`--robot emulator`, the default; L2 trials take 46-59 s of wall time at the default
//!   `--speedup 4`) and a real UR5e (`--robot <ip>`: dashboard checks and a confirmation first);
//! - [`config`]: `config/trial.toml` (files, rates, workspace → robot base transform);
//! - [`log`]: the trial log (`trial.mcap`, `indicators.csv`, `robot.csv`, `summary.json`,
//!   `report.html`), fed directly by the runtime.

mod backend;
#[cfg(feature = "ur-rtde")]
mod backend_ur_rtde;
pub mod config;
mod control;
mod cue_cycle;
mod cues;
mod events;
#[cfg(feature = "vision")]
mod live;
mod log;
pub mod operator;
mod priority;
pub(crate) mod prompt;
mod report;
pub mod runtime;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::Error;
use clap::Args;
use policies::PolicyKind;

pub(crate) use backend::rtde_runtime;
#[allow(unused_imports)] // for the experiment runner
pub(crate) use cues::CueSource;
pub(crate) use log::SUMMARY_FILE;
pub(crate) use log::summary::episodes;
pub use runtime::{TrialSpec, run_simulated};

/// Arguments of `hrc-adapt trial`.
#[derive(Debug, Args)]
pub struct TrialArgs {
    /// Participant id, used in the run folder name: 1 to 32 letters, digits, `_` or `-`
    /// ([A-Za-z0-9_-]{1,32}), so it cannot lead out of `--out-root`.
    #[arg(long, default_value = "P00", value_parser = participant_id)]
    participant: String,
    /// Task complexity level: L1, L2 or L3.
    #[arg(long, default_value = "L2")]
    condition: String,
    /// Policy: adaptive or fixed.
    #[arg(long, default_value = "adaptive")]
    policy: String,
    /// Seed of the simulated operator.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Trial configuration (default: the shipped config/trial.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Robot: `emulator` (in-process controller emulator over loopback RTDE, paced on its
    /// clock), `sim` (in-process, mock clock, deterministic) or a UR5e's address.
    #[arg(long, default_value = "emulator")]
    robot: String,
    /// How the robot is driven: `native` (our RTDE client and control program) or `ur_rtde`
    /// (SDU ur_rtde 1.6.5 and its control script; a build with `--features ur-rtde`).
    #[arg(long, default_value = "native", value_parser = ["native", "ur_rtde"])]
    robot_backend: String,
    /// `--robot emulator`: controller cycles the emulator runs per 2 ms of wall time
    /// (default 4; a live camera needs 1, its default then), 1..=100: one cycle every
    /// 2 ms / N of wall time, and the trial loop already skips most samples far below 100.
    #[arg(long, value_parser = crate::trial::speedup_parser())]
    speedup: Option<u32>,
    /// Replay this recorded cue CSV (the `assess::io::cue_csv` format) instead of the simulated
    /// operator: sample-and-hold by time; the trial ends when the file ends ("cues_ended") or
    /// the task completes. The recorded operator does not react to the robot. `camera` (a
    /// RealSense camera with feature `realsense`, else the first webcam) or `webcam:N` take
    /// the cues from a live camera instead; the trial fails if there is none. The run folder
    /// then holds cues and landmarks only, no images (see --store-video).
    #[arg(long)]
    cues: Option<PathBuf>,
    /// Live camera options (with `--cues camera` or `webcam:N`).
    #[command(flatten)]
    camera: crate::vision_cmd::CameraArgs,
    /// With a live camera: ALSO STORE THE RAW CAMERA IMAGES here (an MJPG .avi, or
    /// a folder of PNGs for a path without extension). Without it no image is stored.
    #[arg(long, value_name = "PATH")]
    store_video: Option<PathBuf>,
    /// Folder under which the run folder is created.
    #[arg(long, default_value = "runs")]
    out_root: PathBuf,
    /// With `--robot <address>`: the controller's RTDE port (default 30004; e.g. the
    /// `--rtde-port` of `hrc-adapt emulate`).
    #[arg(long)]
    rtde_port: Option<u16>,
    /// With `--robot <address>`: its dashboard port (default 29999).
    #[arg(long)]
    dashboard_port: Option<u16>,
    /// With `--robot <address>`: the script port our control program is sent to (default
    /// 30002, the secondary interface).
    #[arg(long)]
    script_port: Option<u16>,
}

/// Runs `hrc-adapt trial`.
pub fn run(args: TrialArgs) -> crate::Result<()> {
    let config = match &args.config {
        Some(p) => config::TrialConfig::from_file(p)?,
        None => config::TrialConfig::shipped()?,
    };
    let spec = TrialSpec {
        participant: args.participant.clone(),
        condition: args.condition.parse()?,
        policy: args.policy.parse::<PolicyKind>()?,
        seed: args.seed,
        config,
    };
    let cues = cue_source(
        args.cues.as_deref(),
        &args.camera,
        args.store_video.as_deref(),
    )?;
    let live = matches!(cues, cues::CueSource::Camera(_));
    let mut robot = robot_choice(&args.robot, args.speedup, live)?;
    let given = [args.rtde_port, args.dashboard_port, args.script_port];
    match &mut robot {
        runtime::RobotChoice::Ur { ports, .. } => {
            let d = backend::UrPorts::default();
            *ports = backend::UrPorts {
                rtde: args.rtde_port.unwrap_or(d.rtde),
                dashboard: args.dashboard_port.unwrap_or(d.dashboard),
                script: args.script_port.unwrap_or(d.script),
            };
        }
        _ => ensure!(
            given.iter().all(Option::is_none),
            Error::usage(
                "--rtde-port, --dashboard-port, --script-port",
                "--rtde-port, --dashboard-port and --script-port need --robot <address>"
            )
        ),
    }
    let robot = with_backend(robot, &args.robot_backend, args.speedup)?;
    // The wall clock is used only for the folder name; a folder of the same second gets a
    // suffix (-2, -3, …).
    let dir = create_run_dir(&run_folder(&args.out_root, &wall_stamp(), &spec))?;
    // The supervisor's per-cycle messages (about 900 warnings per L2 trial) would bury the
    // live display: the trial thread logs warnings of the trial itself and errors only, unless
    // RUST_LOG says otherwise. Every verdict is in trial.mcap (/robot/command), and the
    // debounced safety events in /safety/events and summary.json.
    let _log = scoped_log(TRIAL_LOG);
    let stop = Arc::new(AtomicBool::new(false));
    install_ctrl_c(stop.clone());
    let bar = runtime::progress_bar(true);
    let started = std::time::Instant::now();
    let out = runtime::run_trial_with_cues(&spec, &robot, &cues, &dir, &stop, &mut |l| {
        runtime::update_bar(&bar, l)
    });
    bar.finish_and_clear();
    if stop.load(Ordering::Relaxed) {
        eprintln!("interrupted: robot stopped, logs closed");
    }
    // Every ending that opened the logs names the run folder (on stdout, as a success does).
    let out = match out {
        Ok(out) => out,
        Err(e) => {
            // A trial that ended before writing anything (a bad config, Ctrl-C at the UR5e's
            // `yes`) leaves no empty run folder behind: `remove_dir` removes only an empty one.
            let _ = std::fs::remove_dir(&dir);
            if let Some(dir) = e.trial_ended().and_then(|t| t.dir.as_ref()) {
                println!("{}", dir.display());
            }
            return Err(e);
        }
    };
    match (&args.cues, live) {
        (None, _) => eprintln!(
            "[simulation] trial on {} finished in {:.1} s wall time",
            args.robot,
            started.elapsed().as_secs_f64()
        ),
        (Some(p), true) => eprintln!(
            "[live camera {}] trial on {} finished in {:.1} s wall time",
            p.display(),
            args.robot,
            started.elapsed().as_secs_f64()
        ),
        (Some(p), false) => eprintln!(
            "[recorded cues {}] trial on {} finished in {:.1} s wall time",
            p.display(),
            args.robot,
            started.elapsed().as_secs_f64()
        ),
    }
    println!("{}", out.display());
    Ok(())
}

/// The pattern of a participant id, which names run folders: [`participant_id`].
pub(crate) const PARTICIPANT_ID_PATTERN: &str = "[A-Za-z0-9_-]{1,32}";

/// `--participant`'s parser (`trial`, `experiment`): an id that matches
/// [`PARTICIPANT_ID_PATTERN`], 1 to 32 ASCII letters, digits, `_` or `-`. It goes into folder
/// names, so `/`, `..`, spaces and anything else are refused before anything is created
/// (issue 10: `--participant ../../x` was taken as given).
pub(crate) fn participant_id(s: &str) -> Result<String, String> {
    let ok = (1..=32).contains(&s.len())
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
    if ok {
        Ok(s.to_owned())
    } else {
        Err(format!(
            "a participant id must match {PARTICIPANT_ID_PATTERN} (1 to 32 letters, digits, \
             `_` or `-`; it names the run folder), got {s:?}"
        ))
    }
}

/// `--speedup`'s parser (`trial`, `experiment`, `emulate`): 1..=
/// [`robot_io::emulator::MAX_SPEEDUP`], so a bad value is a usage error naming the range.
pub(crate) fn speedup_parser() -> clap::builder::RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..=i64::from(robot_io::emulator::MAX_SPEEDUP))
}

/// The robot from `--robot` and `--speedup`: `sim`, `emulator` or a UR5e's address. A live
/// camera needs real time: no `sim` (mock clock) and an emulator at speed-up 1 (its default
/// then; 4 otherwise).
pub(crate) fn robot_choice(
    robot: &str,
    speedup: Option<u32>,
    live: bool,
) -> crate::Result<runtime::RobotChoice> {
    Ok(match robot {
        "sim" if live => {
            return Err(Error::usage(
                "--robot",
                "--robot sim runs on a mock clock as fast as the CPU allows, which a live \
                 camera cannot follow; use --robot emulator (real time with a camera) or a UR5e",
            ));
        }
        "sim" => runtime::RobotChoice::Sim,
        "emulator" => {
            let speedup = match (speedup, live) {
                (Some(s), true) if s != 1 => {
                    return Err(Error::usage(
                        "--speedup",
                        format!(
                            "--speedup {s}: a live camera runs in real time, so the emulator \
                             must too (--speedup 1, the default with a camera)"
                        ),
                    ));
                }
                (Some(s), _) => s,
                (None, true) => 1,
                (None, false) => 4,
            };
            runtime::RobotChoice::Emulator { speedup }
        }
        host => runtime::RobotChoice::Ur {
            host: host.to_owned(),
            ports: backend::UrPorts::default(),
        },
    })
}

/// `robot` driven through `backend` (`--robot-backend`): `native` leaves it as it is;
/// `ur_rtde` takes the emulator or a UR5e on UR's standard ports (ur_rtde's are fixed), not
/// the mock-clock `sim`.
///
/// The emulator runs in real time under ur_rtde (`--speedup 1`, its default then): ur_rtde's
/// control script has no servo feedforward, so a servo target must come every controller
/// cycle, which the trial loop does only in real time. Sped up, the held targets made the
/// simulated arm's servo saturate its acceleration (an L1 trial at speedup 4: jerk RMS 196
/// rad/s³ against 0.7 on the native backend).
pub(crate) fn with_backend(
    robot: runtime::RobotChoice,
    backend: &str,
    speedup: Option<u32>,
) -> crate::Result<runtime::RobotChoice> {
    use runtime::RobotChoice as R;
    Ok(match (backend, robot) {
        ("native", r) => r,
        ("ur_rtde", R::Sim) => {
            return Err(Error::usage(
                "--robot-backend",
                "--robot-backend ur_rtde drives a controller over RTDE: use --robot emulator or \
                 --robot <address>, not --robot sim",
            ));
        }
        ("ur_rtde", R::Emulator { .. }) => match speedup {
            None | Some(1) => R::EmulatorUrRtde { speedup: 1 },
            Some(s) => {
                return Err(Error::usage(
                    "--speedup",
                    format!(
                        "--speedup {s}: with --robot-backend ur_rtde the emulator runs in real \
                         time (--speedup 1, the default then): ur_rtde's control script has no \
                         servo feedforward, so the trial must send a target every cycle"
                    ),
                ));
            }
        },
        ("ur_rtde", R::Ur { host, ports }) => {
            ensure!(
                ports == backend::UrPorts::default(),
                Error::usage(
                    "--rtde-port, --dashboard-port, --script-port",
                    "ur_rtde uses UR's fixed ports (30004, 29999, 30003): the port options \
                     need --robot-backend native"
                )
            );
            R::UrRtde { host }
        }
        ("ur_rtde", r) => r,
        (other, _) => {
            return Err(Error::usage(
                "--robot-backend",
                format!("{other:?}: expected `native` or `ur_rtde`"),
            ));
        }
    })
}

/// The error for `--robot-backend ur_rtde` in a build without it.
#[cfg(not(feature = "ur-rtde"))]
pub(crate) fn no_ur_rtde_feature() -> Error {
    Error::usage(
        "--robot-backend",
        "this build has no ur_rtde backend: run scripts/setup, then build with \
         `cargo build --release --features ur-rtde`",
    )
}

/// The trial's cue source from `--cues`: none → simulated operator; `camera` / `webcam:N` →
/// live camera; anything else → a recorded cue CSV. Camera options without a camera are
/// refused.
pub(crate) fn cue_source(
    cues: Option<&std::path::Path>,
    camera: &crate::vision_cmd::CameraArgs,
    store_video: Option<&std::path::Path>,
) -> crate::Result<cues::CueSource> {
    use crate::vision_cmd::CueInput;
    let input = match cues {
        None => None,
        Some(p) => match p.to_str() {
            Some(s) if s == "camera" || s.starts_with("webcam:") => Some(CueInput::parse(p)?),
            _ => None,
        },
    };
    let Some(input) = input else {
        let c = camera;
        let given: Vec<&str> = [
            (c.extrinsics.is_some(), "--extrinsics"),
            (c.intrinsics.is_some(), "--intrinsics"),
            (c.lite, "--lite"),
            (store_video.is_some(), "--store-video"),
        ]
        .into_iter()
        .filter_map(|(given, name)| given.then_some(name))
        .collect();
        ensure!(
            given.is_empty(),
            Error::usage(
                "--extrinsics, --intrinsics, --lite, --store-video",
                format!(
                    "{} need{} a live camera (--cues camera or webcam:N)",
                    given.join(", "),
                    if given.len() == 1 { "s" } else { "" }
                )
            )
        );
        return Ok(cues.map_or(cues::CueSource::Simulated, |p| {
            cues::CueSource::Recorded(p.to_path_buf())
        }));
    };
    // The operator's positions drive the robot's separation monitoring (SAF-REQ-007 and the
    // QP's separation limits): without extrinsics they would be in the camera frame.
    ensure!(
        camera.extrinsics.is_some(),
        Error::usage(
            "--extrinsics",
            "a live camera in a trial needs --extrinsics (from `hrc-adapt calibrate`): the \
             operator's head and hand positions drive the robot's separation monitoring, and \
             without extrinsics they would be in the camera frame, not the workspace frame"
        )
    );
    Ok(cues::CueSource::Camera(cues::CameraSpec {
        input,
        camera: camera.clone(),
        store_video: store_video.map(std::path::Path::to_path_buf),
        require_depth: false,
        station: None, // set from the workspace when the trial loads it
    }))
}

/// The log filter while a trial runs, unless `RUST_LOG` says otherwise: errors, and the
/// trial's own warnings.
pub(crate) const TRIAL_LOG: &str = "error,hrc_adapt=warn";

/// Logs to stderr with `RUST_LOG`'s filter, else `default`, on this thread until the guard is
/// dropped.
pub(crate) fn scoped_log(default: &str) -> tracing::subscriber::DefaultGuard {
    let filter =
        tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| default.into());
    tracing::subscriber::set_default(
        tracing_subscriber::fmt()
            .with_env_filter(filter)
            .with_writer(std::io::stderr)
            .finish(),
    )
}

/// Sets `stop` on every Ctrl-C (a small thread with a current-thread tokio runtime).
pub(crate) fn install_ctrl_c(stop: Arc<AtomicBool>) {
    std::thread::spawn(move || {
        let Ok(rt) = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
        else {
            return;
        };
        while rt.block_on(tokio::signal::ctrl_c()).is_ok() {
            stop.store(true, Ordering::Relaxed);
        }
    });
}

/// The run folder a trial wants under `out_root`: `<stamp>-<participant>-<condition>-<policy>`
/// (`stamp` from [`wall_stamp`], injected for tests). [`create_run_dir`] makes it unique.
pub(crate) fn run_folder(out_root: &Path, stamp: &str, spec: &TrialSpec) -> PathBuf {
    out_root.join(format!(
        "{stamp}-{}-{}-{}",
        spec.participant,
        spec.condition.as_str(),
        spec.policy.as_str()
    ))
}

/// Most suffixes [`create_run_dir`] tries (`-2` … `-999`) before it gives up.
const MAX_RUN_DIR_SUFFIX: u32 = 999;

/// Creates a new, empty run folder at `wanted`, or at `wanted-2`, `wanted-3`, … when that
/// exists (two runs started in the same second), and returns it. The leaf is created
/// exclusively (`create_dir`, not `create_dir_all`), so two processes never share a folder;
/// the parents are created as needed. Used by `trial` and `experiment` (issue 10).
pub(crate) fn create_run_dir(wanted: &Path) -> crate::Result<PathBuf> {
    let (Some(parent), Some(name)) = (wanted.parent(), wanted.file_name()) else {
        return Err(Error::data(wanted.display(), "cannot be a run folder"));
    };
    if !parent.as_os_str().is_empty() {
        std::fs::create_dir_all(parent).map_err(Error::io("create", parent))?;
    }
    for n in 1..=MAX_RUN_DIR_SUFFIX {
        let dir = if n == 1 {
            wanted.to_path_buf()
        } else {
            let mut leaf = name.to_os_string();
            leaf.push(format!("-{n}"));
            parent.join(leaf)
        };
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => {
                return Err(Error::io("create", &dir)(e));
            }
        }
    }
    Err(Error::data(
        wanted.display(),
        format!("exists, and so do its suffixes -2 … -{MAX_RUN_DIR_SUFFIX}"),
    ))
}

/// `YYYYmmdd-HHMMSS` (UTC) of the wall clock, for folder names only.
pub(crate) fn wall_stamp() -> String {
    let (y, m, d, hh, mm, ss) = utc_now();
    format!("{y:04}{m:02}{d:02}-{hh:02}{mm:02}{ss:02}")
}

/// `YYYY-mm-ddTHH:MM:SSZ` of the wall clock (the log's `started_utc`).
pub(crate) fn utc_now_iso() -> String {
    let (y, m, d, hh, mm, ss) = utc_now();
    format!("{y:04}-{m:02}-{d:02}T{hh:02}:{mm:02}:{ss:02}Z")
}

/// The wall clock's civil UTC date and time.
fn utc_now() -> (i64, i64, i64, u64, u64, u64) {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d, rem / 3600, rem % 3600 / 60, rem % 60)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision_cmd::CameraArgs;
    use std::path::Path;

    #[test]
    fn two_trials_started_in_the_same_second_get_different_run_folders() {
        // Issue 10: both trials of one UTC second wrote into one folder. The stamp is
        // injected, so "the same second" needs no sleep.
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("runs");
        let spec = runtime::test_spec(operator::Level::L1, 1, 2.0);
        let wanted = run_folder(&root, "20260101-120000", &spec);
        assert_eq!(
            wanted,
            root.join("20260101-120000-P01-L1-adaptive"),
            "the README's naming"
        );
        let first = create_run_dir(&wanted).unwrap();
        let second = create_run_dir(&wanted).unwrap();
        let third = create_run_dir(&wanted).unwrap();
        assert_eq!(first, wanted);
        assert_eq!(second, root.join("20260101-120000-P01-L1-adaptive-2"));
        assert_eq!(third, root.join("20260101-120000-P01-L1-adaptive-3"));
        // Both trials run, each into its own folder, and neither log is touched by the other.
        let a = run_simulated(&spec, &first, false).unwrap();
        let b = run_simulated(&spec, &second, false).unwrap();
        assert_ne!(a, b);
        for d in [&a, &b] {
            assert!(d.join("summary.json").is_file() && d.join("trial.mcap").is_file());
        }
        // A file of that name is not a folder to write into: the next suffix is taken.
        std::fs::write(root.join("blocked"), "").unwrap();
        assert!(create_run_dir(&root.join("blocked")).is_ok_and(|d| d.ends_with("blocked-2")));
    }

    #[test]
    fn a_trial_that_fails_before_writing_leaves_no_empty_run_folder() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("runs");
        // Only the workspace file is missing: the others are the shipped ones.
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
        let mut config = config::SHIPPED_TOML.to_owned();
        for name in ["handover.toml", "policy-adaptive.toml", "assess.toml"] {
            let path = shipped.join(name).display().to_string();
            config = config.replace(&format!("\"{name}\""), &format!("{path:?}"));
        }
        config = config.replace("example-workspace.toml", "missing-workspace.toml");
        let cfg = tmp.path().join("trial.toml");
        std::fs::write(&cfg, config).unwrap();
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: TrialArgs,
        }
        let args = <Cli as clap::Parser>::try_parse_from([
            "trial".as_ref(),
            "--robot".as_ref(),
            "sim".as_ref(),
            "--config".as_ref(),
            cfg.as_os_str(),
            "--out-root".as_ref(),
            root.as_os_str(),
        ] as [&std::ffi::OsStr; 7])
        .unwrap()
        .args;
        let e = run(args).unwrap_err().with_causes().to_string();
        assert!(e.contains("missing-workspace.toml"), "{e}");
        assert_eq!(std::fs::read_dir(&root).unwrap().count(), 0);
    }

    #[test]
    fn a_trial_never_writes_into_a_folder_holding_another_trials_log() {
        // At a077dd5 TrialLog::create reused the folder and overwrote the files in it.
        let tmp = tempfile::tempdir().unwrap();
        let spec = runtime::test_spec(operator::Level::L1, 1, 2.0);
        let dir = tmp.path().join("run");
        std::fs::create_dir(&dir).unwrap();
        std::fs::write(dir.join("trial.mcap"), "another trial's log").unwrap();
        let e = run_simulated(&spec, &dir, false)
            .unwrap_err()
            .with_causes()
            .to_string();
        assert!(
            e.contains("trial.mcap") && e.contains("another trial"),
            "{e}"
        );
        assert_eq!(
            std::fs::read_to_string(dir.join("trial.mcap")).unwrap(),
            "another trial's log"
        );
        assert!(!dir.join("summary.json").exists());
    }

    #[test]
    fn a_live_camera_needs_real_time() {
        // Without a camera: sim, and the emulator at 4 by default.
        assert!(matches!(
            robot_choice("sim", None, false).unwrap(),
            runtime::RobotChoice::Sim
        ));
        assert!(matches!(
            robot_choice("emulator", None, false).unwrap(),
            runtime::RobotChoice::Emulator { speedup: 4 }
        ));
        // With one: the emulator at 1 by default, other speed-ups and sim refused.
        assert!(matches!(
            robot_choice("emulator", None, true).unwrap(),
            runtime::RobotChoice::Emulator { speedup: 1 }
        ));
        let e = robot_choice("emulator", Some(4), true)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--speedup 4"), "{e}");
        let e = robot_choice("sim", None, true).unwrap_err().to_string();
        assert!(e.contains("mock clock"), "{e}");
        assert!(matches!(
            robot_choice("192.168.1.10", None, true).unwrap(),
            runtime::RobotChoice::Ur { host, ports } if host == "192.168.1.10" && ports == backend::UrPorts::default()
        ));
    }

    #[test]
    fn a_policy_delay_too_long_for_a_duration_is_refused_not_a_panic() {
        // Issue 10: `rules.none.start_delay_s = 1e20` passed validation, then panicked the
        // trial ("cannot convert float seconds to Duration"), exit 101 and no summary.
        let tmp = tempfile::tempdir().unwrap();
        let table = tmp.path().join("policy.toml");
        let shipped = policies::SHIPPED_TOML;
        let at = shipped.find("[rules.none]").unwrap() + "[rules.none]".len();
        let text = format!("{}\nstart_delay_s = 1e20{}", &shipped[..at], &shipped[at..]);
        let text = text.replacen("start_delay_s = 0.5", "", 1);
        std::fs::write(&table, text).unwrap();
        let mut spec = runtime::test_spec(operator::Level::L1, 1, 2.0);
        spec.config.policy_table = table;
        let out = tmp.path().join("run");
        let e = run_simulated(&spec, &out, false)
            .unwrap_err()
            .with_causes()
            .to_string();
        assert!(e.contains("rules.none.start_delay_s"), "{e}");
    }

    #[test]
    fn motion_adaptation_bounds_timings_and_fails_closed_instead_of_panicking() {
        use std::time::Duration;
        let max = Duration::from_secs(600);
        let mut a = policies::Adaptation::NOMINAL;
        for (s, want) in [
            (1.5, Duration::from_millis(1500)),
            (-3.0, Duration::ZERO),
            (f64::NEG_INFINITY, Duration::ZERO),
            (601.0, max),
            (1e20, max),
            (f64::INFINITY, max),
            (f64::NAN, max),
        ] {
            a.timing.start_delay_s = s;
            a.timing.min_approach_duration_s = s;
            let m = runtime::motion_adaptation(&a);
            assert_eq!(
                (m.start_delay, m.min_approach_duration),
                (want, want),
                "{s}"
            );
        }
    }

    #[test]
    fn cue_sources_from_the_command_line() {
        let cam = CameraArgs::default();
        assert_eq!(
            cue_source(None, &cam, None).unwrap(),
            cues::CueSource::Simulated
        );
        assert_eq!(
            cue_source(Some(Path::new("run.csv")), &cam, None).unwrap(),
            cues::CueSource::Recorded("run.csv".into())
        );
        // A live camera needs the extrinsics: its positions drive separation monitoring.
        let e = cue_source(Some(Path::new("webcam:2")), &cam, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs --extrinsics"), "{e}");
        let calibrated = CameraArgs {
            extrinsics: Some("extrinsics.toml".into()),
            ..CameraArgs::default()
        };
        assert!(matches!(
            cue_source(Some(Path::new("webcam:2")), &calibrated, None).unwrap(),
            cues::CueSource::Camera(_)
        ));
        // Camera options without a camera are refused, naming them.
        let e = cue_source(None, &cam, Some(Path::new("v.avi")))
            .unwrap_err()
            .to_string();
        assert!(e.contains("--store-video"), "{e}");
    }
}
