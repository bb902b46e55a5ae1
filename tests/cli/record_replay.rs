//! `hrc-adapt record` against `hrc-adapt emulate --trace`, both as separate processes
//! (issue 11): what `record` writes, `emulate --trace` replays bit for bit, first row
//! included, and a second recording of that replay is the first one again.
//!
//! The source is a synthetic 500 Hz trace that this test writes (SIMULATED values chosen to
//! be awkward for a text round trip: 17 significant digits, subnormals, −0.0, large and tiny
//! magnitudes), so every column of every row checks the CSV writer, the trace parser, the
//! replay and the RTDE encoding together.
//!
//! - native backend: the recording is the source's rows 0…n−1 exactly (every package);
//! - ur_rtde backend (feature `ur-rtde`): ur_rtde keeps only its newest sample (its RTDE
//!   class even skips a package when a newer one is buffered), so its recording is source
//!   rows in order, each bit for bit; a sample replaced before `record` polled it is missing,
//!   the first row included, and the counts are printed, not judged (they depend on
//!   scheduling: none missed on a quiet machine here, hundreds with two busy loops on its two
//!   cores). What it wrote is then checked as a trace: its replay, recorded by our client,
//!   is that file bit for bit from its first row.
//!
//! ur_rtde's RTDE port is fixed (30004), so each ur_rtde test has a loopback address of its
//! own (127.0.0.9, 127.0.0.10); every other port is ephemeral.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use robot_io::trace::{STATE_FIELD_NAMES, TraceWriter, WriteOptions, state_to_row};
use robot_io::{RobotState, Trace};

mod common;
use common::{BIN, Emulate};

/// Every wait here is bounded by this.
const DEADLINE: Duration = Duration::from_secs(120);

/// Rows of the synthetic source: 8 s at 500 Hz, longer than any recording here.
const SOURCE_ROWS: usize = 4000;

/// Rows a recording gathers before it is stopped.
const RECORD_ROWS: usize = 300;

/// A deterministic value in a few awkward classes, for row `k`, column `c`.
fn awkward(k: usize, c: usize) -> f64 {
    let x = (k * 44 + c) as u64;
    // splitmix64: reproducible bits without a dependency.
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    let unit = (z >> 11) as f64 / (1u64 << 53) as f64; // [0, 1), 53 bits
    match z % 6 {
        0 => unit * std::f64::consts::TAU - std::f64::consts::PI,
        1 => (unit - 0.5) * 1e-300,
        2 => f64::from_bits(1 + (z >> 20)), // a subnormal
        3 => -0.0,
        4 => (unit - 0.5) * 1e12,
        _ => 0.1 + 0.2 * unit,
    }
}

/// The synthetic source (SIMULATED): every robot-state field, row `k` at
/// 1234.567 + 0.002·k [s]; integer fields vary as integers.
fn write_source(path: &Path) {
    let file = std::fs::File::create(path).unwrap();
    let mut w = TraceWriter::new(
        std::io::BufWriter::new(file),
        &STATE_FIELD_NAMES,
        &WriteOptions::record_py(),
    )
    .unwrap();
    let mut row = [0.0; 44];
    for k in 0..SOURCE_ROWS {
        let mut c = 0;
        let mut next = || {
            c += 1;
            awkward(k, c)
        };
        let mut s = RobotState {
            timestamp_s: 1234.567 + 0.002 * k as f64,
            ..RobotState::default()
        };
        for v in s
            .actual_q
            .iter_mut()
            .chain(s.actual_qd.iter_mut())
            .chain(s.target_q.iter_mut())
            .chain(s.target_qd.iter_mut())
            .chain(s.actual_tcp_pose.iter_mut())
            .chain(s.actual_tcp_speed.iter_mut())
        {
            *v = next();
        }
        s.speed_scaling = next();
        s.target_speed_fraction = next();
        s.robot_mode = (k % 10) as i32 - 1;
        s.safety_mode = (k % 13) as i32;
        s.runtime_state = (k % 7) as u32;
        s.robot_status_bits = (k % 16) as u32;
        s.safety_status_bits = (k % 2048) as u32;
        state_to_row(&s, &mut row);
        w.write_row(&row).unwrap();
    }
    w.flush().unwrap();
}

/// `hrc-adapt emulate --trace <csv>` on `addr` with RTDE on `rtde_port` (0: an ephemeral
/// port) and the other ports ephemeral.
fn emulate_trace(csv: &Path, addr: &str, rtde_port: u16) -> Emulate {
    Emulate::start_on_port(
        &["--trace", csv.to_str().unwrap(), "--bind", addr],
        rtde_port,
    )
}

/// `hrc-adapt record` from `addr:port` into `out` with `backend`, stopped by SIGINT (as
/// Ctrl-C) once `done` holds for what `out` holds; the recorder's stderr.
fn record(addr: &str, port: u16, backend: &str, out: &Path, done: impl Fn(&str) -> bool) -> String {
    let child = Command::new(BIN)
        .args(["record", "--robot", addr, "--port", &port.to_string()])
        .args(["--robot-backend", backend])
        .arg("--out")
        .arg(out)
        .env("RUST_LOG", "info")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start hrc-adapt record");
    let start = Instant::now();
    let mut child = child;
    loop {
        if std::fs::read_to_string(out).is_ok_and(|t| done(&t)) {
            break;
        }
        if let Some(status) = child.try_wait().unwrap() {
            let (_, _, stderr) = common::wait(child);
            panic!("record ended by itself ({status}):\n{stderr}");
        }
        assert!(start.elapsed() < DEADLINE, "record never wrote its rows");
        std::thread::sleep(Duration::from_millis(20));
    }
    let ok = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill -INT");
    let (status, _, stderr) = common::wait(child);
    assert!(status.success(), "record after Ctrl-C: {status}\n{stderr}");
    stderr
}

/// How a recording relates to the replay it recorded.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Client {
    /// Receives every package (our client): the recording starts at the source's row 0 and
    /// has every row, each as often as the replay held it (once per 2 ms).
    EveryPackage,
    /// Keeps only its newest sample (ur_rtde): rows may be missing, none repeated.
    NewestOnly,
}

/// What [`assert_replays`] counted.
#[derive(Debug)]
struct Replayed {
    /// The source row the recording starts at.
    first: usize,
    /// Source rows the recording does not have.
    missed: usize,
}

/// `recorded` is a recording of a replay of `source`, bit for bit: every row equal in every
/// column (by name) to the source row with its timestamp, in source order. With
/// [`Client::EveryPackage`] it starts at row 0, misses no row, and repeats a row only where
/// the replay held it (a gap of more than one period after it, or the last row).
fn assert_replays(source: &Trace, recorded: &Trace, client: Client) -> Replayed {
    assert!(recorded.len() > RECORD_ROWS / 2, "{} rows", recorded.len());
    let names: Vec<&str> = STATE_FIELD_NAMES.to_vec();
    let cols = |t: &Trace| -> Vec<usize> {
        names
            .iter()
            .map(|n| t.column_index(n).unwrap_or_else(|| panic!("no column {n}")))
            .collect()
    };
    let (src_cols, rec_cols) = (cols(source), cols(recorded));
    let ts = |t: &Trace, i: usize| t.timestamp(i).map(f64::to_bits);
    // Row i's source row, searched forward from `from`.
    let find = |from: usize, t: u64| (from..source.len()).find(|&j| ts(source, j) == Some(t));
    let t0 = ts(recorded, 0).unwrap();
    let first = find(0, t0).unwrap_or_else(|| panic!("recorded row 0 is no source row"));
    if client == Client::EveryPackage {
        assert_eq!(
            first, 0,
            "the recording starts at source row {first}, not row 0"
        );
    }
    let (mut j, mut missed) = (first, first);
    for i in 0..recorded.len() {
        let t = ts(recorded, i).unwrap();
        if i > 0 && Some(t) == ts(source, j) {
            // A repeat: only where the replay held row j for more than one period.
            let held = match source.timestamp(j + 1) {
                None => true,
                Some(next) => next - source.timestamp(j).unwrap() > 1.5 * 0.002,
            };
            assert!(
                client == Client::EveryPackage && held,
                "recorded row {i} repeats source row {j}, which the replay did not hold"
            );
        } else if i > 0 {
            let k = find(j + 1, t).unwrap_or_else(|| {
                panic!(
                    "recorded row {i} (t = {}) is no later source row",
                    f64::from_bits(t)
                )
            });
            missed += k - j - 1;
            if client == Client::EveryPackage {
                assert_eq!(
                    k,
                    j + 1,
                    "recorded row {i}: source rows {}..{k} missing",
                    j + 1
                );
            }
            j = k;
        }
        for (c, name) in names.iter().enumerate() {
            let a = source.value_at(j, src_cols[c]).unwrap();
            let b = recorded.value_at(i, rec_cols[c]).unwrap();
            assert_eq!(
                a.to_bits(),
                b.to_bits(),
                "row {i} (source row {j}), {name}: recorded {b:e}, source {a:e}"
            );
        }
    }
    Replayed { first, missed }
}

/// The client kind of a `record --robot-backend`.
fn client(backend: &str) -> Client {
    if backend == "native" {
        Client::EveryPackage
    } else {
        Client::NewestOnly
    }
}

/// Source → replay → recording `a` (with `first`) → replay of `a` → recording `b` (with
/// `second`), the emulator on `addr` with RTDE on `port` (0: ephemeral; ur_rtde needs 30004).
fn round_trip(addr: &str, port: u16, first: &str, second: &str) {
    let dir = tempfile::tempdir().unwrap();
    let src_path = dir.path().join("source.csv");
    write_source(&src_path);
    let source = Trace::read(&src_path).unwrap();
    assert_eq!(source.len(), SOURCE_ROWS);

    let a_path = dir.path().join("a.csv");
    let stderr = {
        let emu = emulate_trace(&src_path, addr, port);
        let rows = |t: &str| t.lines().count() > RECORD_ROWS;
        record(addr, emu.port("rtde"), first, &a_path, rows)
    };
    assert!(stderr.contains("wrote"), "{stderr}");
    let a = Trace::read(&a_path).unwrap();
    let got = assert_replays(&source, &a, client(first));
    eprintln!(
        "{first} recording of the source: {} rows from source row {}, {} missed",
        a.len(),
        got.first,
        got.missed
    );

    // The replay of `a`, recorded until it reaches `a`'s last row (which it then holds).
    let b_path = dir.path().join("b.csv");
    {
        let last = a.timestamp(a.len() - 1).unwrap().to_bits();
        let reached = |t: &str| {
            t.lines()
                .filter_map(|l| l.split(' ').next()?.parse::<f64>().ok())
                .any(|x| x.to_bits() == last)
        };
        let emu = emulate_trace(&a_path, addr, port);
        record(addr, emu.port("rtde"), second, &b_path, reached);
    }
    let b = Trace::read(&b_path).unwrap();
    let got = assert_replays(&a, &b, client(second));
    eprintln!(
        "{second} recording of its replay: {} rows from row {}, {} missed",
        b.len(),
        got.first,
        got.missed
    );
}

#[test]
fn native_record_is_replayed_bit_for_bit_first_row_included() {
    round_trip("127.0.0.1", 0, "native", "native");
}

/// What ur_rtde records (lossy, see the module docs) is a trace that the emulator replays bit
/// for bit, first row included: our client records that replay, every package.
#[cfg(feature = "ur-rtde")]
#[test]
fn ur_rtde_record_is_replayed_bit_for_bit_first_row_included() {
    round_trip("127.0.0.9", 30_004, "ur_rtde", "native");
}

/// ur_rtde recording a replay of our client's recording: each row it saw is bit for bit.
#[cfg(feature = "ur-rtde")]
#[test]
fn ur_rtde_records_a_replay_of_a_native_recording_bit_for_bit() {
    round_trip("127.0.0.10", 30_004, "native", "ur_rtde");
}

#[test]
fn ur_rtde_record_refuses_fields_and_ports_it_cannot_honour() {
    for (option, value, named) in [
        ("--fields", "timestamp,actual_q", "--robot-backend native"),
        ("--port", "31004", "30004"),
    ] {
        let (status, _, stderr) = common::run(&[
            "record",
            "--robot",
            "127.0.0.1",
            "--out",
            "/dev/null",
            "--robot-backend",
            "ur_rtde",
            option,
            value,
        ]);
        assert!(!status.success(), "{option} {value}");
        assert!(stderr.contains(named), "{option} {value}: {stderr}");
    }
}
