//! What the tests of the `hrc-adapt` binary share: a trial config with absolute paths and
//! chosen keys, running the binary to its end, and the run folder it prints.

#![allow(dead_code)] // each test binary uses its own part

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// The binary under test.
pub(crate) const BIN: &str = env!("CARGO_BIN_EXE_hrc-adapt");
/// Every wait of these tests is bounded by this (a hang detector, not a speed check).
pub(crate) const DEADLINE: Duration = Duration::from_secs(900);

/// The shipped `config/trial.toml` written to `dir/trial.toml` with absolute paths to the
/// files it names and each `(key, value)` of `set` replacing that key's line.
pub(crate) fn trial_config(dir: &Path, set: &[(&str, &str)]) -> PathBuf {
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let mut text = std::fs::read_to_string(config.join("trial.toml")).unwrap();
    for file in [
        "example-workspace.toml",
        "handover.toml",
        "policy-adaptive.toml",
        "assess.toml",
    ] {
        let abs = config.join(file);
        text = text.replace(
            &format!("\"{file}\""),
            &format!("{:?}", abs.display().to_string()),
        );
    }
    for (key, value) in set {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("{key} = ")))
            .unwrap_or_else(|| panic!("{key} in config/trial.toml"))
            .to_owned();
        text = text.replace(&line, &format!("{key} = {value}"));
    }
    let path = dir.join("trial.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Waits for `child` to end (killed after [`DEADLINE`]): its exit status, stdout and stderr
/// (both piped).
pub(crate) fn wait(mut child: Child) -> (ExitStatus, String, String) {
    let start = Instant::now();
    let mut stdout = child.stdout.take().unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let out = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stdout.read_to_string(&mut s);
        s
    });
    let err = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > DEADLINE {
            let _ = child.kill();
            panic!("the process did not end");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    (status, out.join().unwrap(), err.join().unwrap())
}

/// Runs `hrc-adapt trial` with `args` to its end and returns its exit status, stdout and
/// stderr.
pub(crate) fn trial(args: &[&str]) -> (ExitStatus, String, String) {
    let mut all = vec!["trial"];
    all.extend_from_slice(args);
    run(&all)
}

/// Runs `hrc-adapt` with `args` (a subcommand first) to its end: exit status, stdout and
/// stderr.
pub(crate) fn run(args: &[&str]) -> (ExitStatus, String, String) {
    let child = Command::new(BIN)
        .args(args)
        .env("RUST_LOG", "warn")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start hrc-adapt");
    wait(child)
}

/// The run folder the trial printed (the last line on stdout that is a folder: ur_rtde's
/// threads print to stdout too, "Reconnecting..." after a silent link), with every file
/// finished (ARCHITECTURE.md, "Files a trial leaves").
pub(crate) fn run_folder(stdout: &str, stderr: &str) -> PathBuf {
    let dir = PathBuf::from(
        stdout
            .lines()
            .rev()
            .find(|l| Path::new(l).is_dir())
            .unwrap_or_else(|| panic!("no run folder printed: {stdout}; stderr: {stderr}")),
    );
    for f in [
        "trial.mcap",
        "indicators.csv",
        "robot.csv",
        "summary.json",
        "report.html",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing in {}", dir.display());
    }
    dir
}

/// `summary.json` of a run folder.
pub(crate) fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap()
}

/// `hrc-adapt emulate` with `args` as a separate process, ready once it prints that it
/// serves; killed (SIGKILL) when dropped.
pub(crate) struct Emulate {
    /// The emulator process.
    pub(crate) child: Child,
    /// Its start-up line ("emulating a UR controller … rtde 127.0.0.1:PORT, …").
    pub(crate) line: String,
}

impl Emulate {
    /// Starts `hrc-adapt emulate <args>` and waits until it serves. An emulator that exits
    /// first (a port taken, a bad trace) panics with everything it printed.
    pub(crate) fn start(args: &[&str]) -> Emulate {
        let mut child = Command::new(BIN)
            .arg("emulate")
            .args(args)
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start hrc-adapt emulate");
        let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
        let mut seen = Vec::new();
        let line = loop {
            match lines.next() {
                Some(Ok(line)) if line.starts_with("emulating a UR controller") => break line,
                Some(Ok(line)) => seen.push(line),
                _ => {
                    let status = child.wait();
                    panic!(
                        "hrc-adapt emulate {args:?} exited before serving ({status:?}):\n{}",
                        seen.join("\n")
                    );
                }
            }
        };
        // Keep draining stderr so the emulator never blocks on a full pipe.
        std::thread::spawn(move || lines.for_each(drop));
        Emulate { child, line }
    }

    /// [`Emulate::start`] with RTDE on `rtde_port` (0: an ephemeral port, as [`Emulate::port`]
    /// then reads it) and the dashboard, secondary and real-time ports ephemeral.
    pub(crate) fn start_on_port(args: &[&str], rtde_port: u16) -> Emulate {
        let rtde_port = rtde_port.to_string();
        let mut all = args.to_vec();
        all.extend_from_slice(&[
            "--rtde-port",
            &rtde_port,
            "--dashboard-port",
            "0",
            "--secondary-port",
            "0",
            "--realtime-port",
            "0",
        ]);
        Emulate::start(&all)
    }

    /// The port of `label ADDR:PORT` in the start-up line (`rtde`, `dashboard`, `script`).
    pub(crate) fn port(&self, label: &str) -> u16 {
        let line = &self.line;
        let at = line
            .find(label)
            .unwrap_or_else(|| panic!("{label} in {line}"));
        let rest = &line[at + label.len()..];
        let addr = rest.trim_start().split([',', ' ', ';']).next().unwrap();
        addr.rsplit(':').next().unwrap().parse().unwrap()
    }

    /// Sends `sig` (`-STOP`, `-CONT`, `-USR1`, …) to the emulator.
    pub(crate) fn signal(&self, sig: &str) {
        let ok = Command::new("kill")
            .args([sig, &self.child.id().to_string()])
            .status()
            .unwrap()
            .success();
        assert!(ok, "kill {sig}");
    }
}

impl Drop for Emulate {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
