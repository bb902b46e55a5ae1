//! Hardware-in-the-loop tests: the real RTDE client against the UR controller emulator over
//! loopback TCP, on ephemeral ports.
//!
//! Determinism: the emulator samples its virtual clock, so what a client receives depends on
//! virtual cycles, not on scheduling. Timeouts are generous (CI runs on 2 shared cores) and no
//! assertion depends on wall-clock tightness, except the watchdog test, which bounds the stop
//! in *virtual* time with a wide margin.

use std::collections::BTreeSet;
use std::time::Duration;

use hrc_adapt_tests::data_dir;
use robot_io::client::{ClientConfig, LinkState, OutputBuffer, RtdeClient};
use robot_io::codec::{FieldType, Value, known_field_type};
use robot_io::dashboard::{DashboardClient, RobotModeReply, SafetyStatus};
use robot_io::emulator::{Emulator, EmulatorConfig, ReplayMode, SimBackend, TraceBackend};
use robot_io::rtde_robot::{RtdeRobot, RtdeRobotConfig};
use robot_io::script::{RegisterMap, ScriptSender};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::trace::Trace;
use robot_io::{
    JointCommand, Robot, RobotIoError, RobotState, robot_mode, runtime_state, safety_mode,
};

/// Every test body runs under this bound.
const TEST_TIMEOUT: Duration = Duration::from_secs(60);
/// Generous per-sample timeout.
const SAMPLE_TIMEOUT: Duration = Duration::from_secs(5);

fn traces() -> Vec<std::path::PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(data_dir().join("rtde-traces"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    v.sort();
    v
}

/// RTDE output names a trace can serve: base names of its columns that RTDE knows and whose
/// columns are all present.
fn servable_fields(trace: &Trace) -> Vec<String> {
    let mut out = Vec::new();
    for name in trace.field_names() {
        let base = if known_field_type(name).is_some() {
            name.clone()
        } else if let Some((b, _)) = name.rsplit_once('_') {
            b.to_owned()
        } else {
            continue;
        };
        let Some(ty) = known_field_type(&base) else {
            continue;
        };
        let complete = if ty.width() == 1 {
            trace.column_index(&base).is_some()
        } else {
            (0..ty.width()).all(|i| trace.column_index(&format!("{base}_{i}")).is_some())
        };
        if complete && !out.contains(&base) {
            out.push(base);
        }
    }
    out
}

/// Nominal period of a trace [s]: median timestamp step.
fn period(trace: &Trace) -> f64 {
    let mut d: Vec<f64> = (1..trace.len())
        .map(|r| trace.timestamp(r).unwrap() - trace.timestamp(r - 1).unwrap())
        .collect();
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

fn client_config(emu: &Emulator, fields: &[String], hz: f64) -> ClientConfig {
    let names: Vec<&str> = fields.iter().map(String::as_str).collect();
    let mut c = ClientConfig::new("127.0.0.1", &names);
    c.port = emu.rtde_addr().port();
    c.frequency_hz = hz;
    // Link loss is tested on its own; elsewhere a loaded CI host must not trigger it.
    c.link_loss_min = Duration::from_secs(3);
    c
}

/// Asserts every field of the sample in `buf` equals the trace row with the same timestamp,
/// bit for bit; returns that row.
fn check_sample_against_trace(trace: &Trace, buf: &OutputBuffer) -> usize {
    check_sample_against_trace_except(trace, buf, "")
}

/// Like [`check_sample_against_trace`], skipping field `skip` (not from the trace).
fn check_sample_against_trace_except(trace: &Trace, buf: &OutputBuffer, skip: &str) -> usize {
    let recipe = buf.recipe();
    let ts = match buf.get("timestamp").unwrap() {
        Value::Double(t) => t,
        other => panic!("timestamp is {other:?}"),
    };
    let row = trace.row_at_time(ts).expect("sample before the trace");
    assert_eq!(
        trace.timestamp(row).unwrap().to_bits(),
        ts.to_bits(),
        "timestamp {ts} is not a recorded one"
    );
    for (name, slot) in recipe.names().iter().zip(recipe.slots()) {
        if name == skip {
            continue;
        }
        let v = buf.read(*slot).unwrap();
        for i in 0..slot.ty.width() {
            let col = if slot.ty.width() == 1 {
                name.clone()
            } else {
                format!("{name}_{i}")
            };
            let recorded = trace.value(row, &col).unwrap();
            let got = v.component(i).unwrap();
            if slot.ty == FieldType::Double
                || matches!(slot.ty, FieldType::Vector3d | FieldType::Vector6d)
            {
                assert_eq!(
                    got.to_bits(),
                    recorded.to_bits(),
                    "{col} at row {row}: got {got:e}, recorded {recorded:e}"
                );
            } else {
                assert_eq!(got, recorded, "{col} at row {row}");
            }
        }
    }
    row
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_trace_replays_bit_identical() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let files = traces();
        assert!(
            files.len() >= 6,
            "expected the bundled traces, found {files:?}"
        );
        for path in files {
            let trace = Trace::read(&path).unwrap();
            let fields = servable_fields(&trace);
            assert!(
                fields.len() > 20,
                "{}: only {} servable fields",
                path.display(),
                fields.len()
            );
            // Sample at twice the recorded rate, so every row is seen at least once.
            let hz = (2.0 / period(&trace)).min(500.0).round();
            let cfg = EmulatorConfig {
                speedup: 20,
                ..EmulatorConfig::ephemeral()
            };
            let backend = TraceBackend::new(trace.clone(), ReplayMode::Hold).unwrap();
            let emu = Emulator::start(cfg, Box::new(backend)).await.unwrap();
            let mut client = RtdeClient::connect(client_config(&emu, &fields, hz))
                .await
                .unwrap();
            let mut buf = client.output_buffer();
            client.start().await.unwrap();
            let last = trace.len() - 1;
            let mut seen = BTreeSet::new();
            let mut prev_row = 0;
            loop {
                let info = client.recv_timeout(&mut buf, SAMPLE_TIMEOUT).await.unwrap();
                assert_eq!(info.dropped, 0);
                assert_eq!(info.epoch, 0);
                let row = check_sample_against_trace(&trace, &buf);
                assert!(row >= prev_row, "rows went backwards");
                prev_row = row;
                seen.insert(row);
                if row == last {
                    break;
                }
            }
            assert_eq!(seen.len(), trace.len(), "{}: rows missing", path.display());
            assert_eq!(client.rejected_packages(), 0);
            assert!(client.last_message().unwrap_or_default().contains("hold"));
            client.close().await;
        }
    })
    .await
    .expect("test timed out");
}

/// Starts a SimRobot-backed emulator at real time, sends our program, connects an RtdeRobot.
async fn sim_setup(map: RegisterMap, hz: f64) -> (Emulator, RtdeRobot) {
    let robot = SimRobot::new(SimConfig::ur5e()).unwrap();
    let emu = Emulator::start(
        EmulatorConfig::ephemeral(),
        Box::new(SimBackend::new(robot)),
    )
    .await
    .unwrap();
    let mut rcfg = RtdeRobotConfig::new("127.0.0.1");
    rcfg.port = emu.rtde_addr().port();
    rcfg.frequency_hz = hz;
    rcfg.registers = map;
    rcfg.link_loss_min = Duration::from_secs(3);
    let mut robot = RtdeRobot::connect(rcfg).await.unwrap();
    ScriptSender::new("127.0.0.1", emu.secondary_addr().port())
        .send_control_program(&map)
        .await
        .unwrap();
    // Wait until the program plays.
    let mut s = RobotState::default();
    for _ in 0..1000 {
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        if s.runtime_state == runtime_state::PLAYING {
            break;
        }
    }
    assert_eq!(
        s.runtime_state,
        runtime_state::PLAYING,
        "the program never started"
    );
    assert_eq!(emu.with_sim(|b| b.program_running()), Some(true));
    (emu, robot)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn servoj_sequence_moves_the_sim_along_it() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        // A slow watchdog: this test is about tracking, not about CI stalls.
        let map = RegisterMap {
            watchdog_hz: 1.0,
            ..RegisterMap::default()
        };
        let (emu, mut robot) = sim_setup(map, 125.0).await;
        let mut s = RobotState::default();
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        let q0 = s.actual_q;
        // 0.2 rad on joint 0 and -0.1 rad on joint 2, in 100 steps, one per received sample.
        let target = |k: usize| {
            let a = (k.min(100) as f64) / 100.0;
            let mut q = q0;
            q[0] += 0.2 * a;
            q[2] -= 0.1 * a;
            q
        };
        let mut max_lag: f64 = 0.0;
        let mut prev = s.actual_q[0];
        for k in 1..=100 {
            robot
                .send(&JointCommand::Servo {
                    q: target(k),
                    lookahead_s: 0.1,
                    gain: 300.0,
                })
                .unwrap();
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
            assert!(
                s.actual_q[0] >= prev - 1e-9,
                "joint 0 moved backwards at step {k}"
            );
            prev = s.actual_q[0];
            max_lag = max_lag.max((target(k)[0] - s.actual_q[0]).abs());
        }
        // Hold the final target until the arm settles.
        let goal = target(100);
        let mut settled = false;
        for _ in 0..1000 {
            robot
                .send(&JointCommand::Servo {
                    q: goal,
                    lookahead_s: 0.1,
                    gain: 300.0,
                })
                .unwrap();
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
            if (0..6).all(|j| (s.actual_q[j] - goal[j]).abs() < 1e-3) {
                settled = true;
                break;
            }
        }
        assert!(settled, "did not reach {goal:?}: at {:?}", s.actual_q);
        assert!(s.actual_q[0] > q0[0] + 0.19, "joint 0 did not follow");
        assert!(max_lag < 0.2, "tracking lag {max_lag} rad");
        let executed = emu.with_sim(|b| b.commands_executed()).unwrap();
        assert!(executed >= 100, "only {executed} commands reached the sim");
        assert_eq!(emu.with_sim(|b| b.watchdog_trips()), Some(0));
    })
    .await
    .expect("test timed out");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watchdog_stops_the_robot_when_commands_stop() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let map = RegisterMap {
            watchdog_hz: 4.0,
            ..RegisterMap::default()
        };
        let period_s = 1.0 / map.watchdog_hz;
        let (emu, mut robot) = sim_setup(map, 125.0).await;
        let mut s = RobotState::default();
        // Move with speedj for 100 samples (0.8 s).
        let qd = [0.2, 0.0, 0.0, 0.0, 0.0, 0.0];
        for _ in 0..100 {
            robot.send(&JointCommand::Speed { qd, acc: 2.0 }).unwrap();
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        }
        assert!(s.actual_qd[0] > 0.1, "not moving: {:?}", s.actual_qd);
        assert_eq!(s.runtime_state, runtime_state::PLAYING);
        let last_command_t = s.timestamp_s;
        // Stop sending. The program must stop and the arm come to rest.
        let mut stopped_at = None;
        for _ in 0..2000 {
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
            if stopped_at.is_none() && s.runtime_state != runtime_state::PLAYING {
                stopped_at = Some(s.timestamp_s);
            }
            if stopped_at.is_some() && s.actual_qd.iter().all(|v| *v == 0.0) {
                break;
            }
        }
        let stopped_at = stopped_at.expect("the watchdog never stopped the program");
        let after = stopped_at - last_command_t;
        assert!(
            after >= period_s - 0.01,
            "stopped after {after} s, before the watchdog period"
        );
        // Generous bound in controller time: the period plus loopback latency under load.
        assert!(after <= period_s + 0.5, "stopped only after {after} s");
        assert!(
            s.actual_qd.iter().all(|v| *v == 0.0),
            "still moving: {:?}",
            s.actual_qd
        );
        assert!(matches!(
            s.runtime_state,
            runtime_state::STOPPED | runtime_state::STOPPING
        ));
        assert_eq!(emu.with_sim(|b| b.watchdog_trips()), Some(1));
        assert_eq!(emu.with_sim(|b| b.program_running()), Some(false));
    })
    .await
    .expect("test timed out");
}

/// Checks samples across reconnects: every trace field bit-identical to a recorded row, and
/// controller time never going back.
struct Checker<'a> {
    trace: &'a Trace,
    last_ts: f64,
    epochs: BTreeSet<u64>,
    samples: u64,
}

impl Checker<'_> {
    fn check(&mut self, buf: &OutputBuffer, epoch: u64) {
        check_sample_against_trace_except(self.trace, buf, "input_int_register_30");
        let ts = buf.get("timestamp").unwrap().component(0).unwrap();
        assert!(
            ts >= self.last_ts,
            "timestamp went back from {} to {ts}",
            self.last_ts
        );
        self.last_ts = ts;
        self.epochs.insert(epoch);
        self.samples += 1;
    }
}

async fn recv_until(
    client: &mut RtdeClient,
    buf: &mut OutputBuffer,
    ck: &mut Checker<'_>,
    pred: &dyn Fn(&OutputBuffer, u64) -> bool,
) {
    loop {
        let info = client
            .recv_timeout(buf, Duration::from_secs(10))
            .await
            .unwrap();
        ck.check(buf, info.epoch);
        if pred(buf, info.epoch) {
            return;
        }
    }
}

async fn recv_n(client: &mut RtdeClient, buf: &mut OutputBuffer, ck: &mut Checker<'_>, n: u64) {
    for _ in 0..n {
        let info = client
            .recv_timeout(buf, Duration::from_secs(10))
            .await
            .unwrap();
        ck.check(buf, info.epoch);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn link_cut_reconnects_with_recipes_and_no_misread_sample() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let trace =
            Trace::read(data_dir().join("rtde-traces/eseries_10hz_recordpy_paused.csv")).unwrap();
        let mut fields = servable_fields(&trace);
        fields.push("input_int_register_30".into());
        let cfg = EmulatorConfig {
            speedup: 2,
            ..EmulatorConfig::ephemeral()
        };
        let backend = TraceBackend::new(trace.clone(), ReplayMode::Hold).unwrap();
        let emu = Emulator::start(cfg, Box::new(backend)).await.unwrap();
        let mut ccfg = client_config(&emu, &fields, 50.0);
        // Link loss after 3 periods (60 ms of controller time), floored at 300 ms of wall time.
        ccfg.link_loss_min = Duration::from_millis(300);
        ccfg.input_recipes = vec![vec!["input_int_register_30".into()]];
        let mut client = RtdeClient::connect(ccfg).await.unwrap();
        let mut buf = client.output_buffer();
        let echo = buf.slot("input_int_register_30").unwrap();
        client.send_inputs(0, &[Value::Int32(41)]).unwrap();
        client.start().await.unwrap();

        let mut ck = Checker {
            trace: &trace,
            last_ts: f64::NEG_INFINITY,
            epochs: BTreeSet::new(),
            samples: 0,
        };
        // Streaming, with our input echoed.
        recv_until(&mut client, &mut buf, &mut ck, &|b, _| {
            b.read(echo).unwrap() == Value::Int32(41)
        })
        .await;
        recv_n(&mut client, &mut buf, &mut ck, 30).await;
        // Cut 1: the emulator closes the connection.
        emu.cut_rtde_links();
        recv_until(&mut client, &mut buf, &mut ck, &|_, e| e >= 1).await;
        assert_eq!(client.link_state(), LinkState::Up);
        // The input recipe is set up again: a new value gets through.
        client.send_inputs(0, &[Value::Int32(43)]).unwrap();
        recv_until(&mut client, &mut buf, &mut ck, &|b, _| {
            b.read(echo).unwrap() == Value::Int32(43)
        })
        .await;
        recv_n(&mut client, &mut buf, &mut ck, 30).await;
        // Cut 2: the link stalls (no package, connection open) long enough for the client
        // to declare it lost; reconnect attempts meet the same silence until it lifts.
        emu.set_rtde_silent(true);
        let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
        while client.reconnects() < 2 {
            assert!(tokio::time::Instant::now() < deadline, "stall not detected");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        emu.set_rtde_silent(false);
        client.send_inputs(0, &[Value::Int32(44)]).unwrap();
        recv_until(&mut client, &mut buf, &mut ck, &|b, e| {
            e >= 2 && b.read(echo).unwrap() == Value::Int32(44)
        })
        .await;
        recv_n(&mut client, &mut buf, &mut ck, 30).await;
        assert!(client.reconnects() >= 2);
        assert_eq!(client.rejected_packages(), 0);
        assert!(ck.epochs.len() >= 3, "epochs seen: {:?}", ck.epochs);
        assert!(ck.samples >= 90);
        client.close().await;
    })
    .await
    .expect("test timed out");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn setup_errors_are_clear() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let robot = SimRobot::new(SimConfig::ur5e()).unwrap();
        let cfg = EmulatorConfig {
            preclaimed_inputs: vec!["input_int_register_0".into()],
            ..EmulatorConfig::ephemeral()
        };
        let emu = Emulator::start(cfg, Box::new(SimBackend::new(robot)))
            .await
            .unwrap();
        let fields = vec!["timestamp".to_owned(), "actual_q".to_owned()];
        let map = RegisterMap::default();

        // IN_USE: a second writer on our registers.
        let mut first = client_config(&emu, &fields, 125.0);
        first.input_recipes = vec![map.input_names()];
        let first = RtdeClient::connect(first.clone()).await.unwrap();
        let mut second = client_config(&emu, &fields, 125.0);
        second.input_recipes = vec![map.input_names()];
        let err = RtdeClient::connect(second).await.unwrap_err();
        match &err {
            RobotIoError::InputsInUse { fields } => assert_eq!(fields, &map.input_names()),
            other => panic!("expected InputsInUse, got {other:?}"),
        }
        let msg = err.to_string();
        assert!(
            msg.contains("already in use") && msg.contains("input_int_register_24"),
            "{msg}"
        );
        // Registers 0-23 claimed by a fieldbus adapter.
        let mut low = client_config(&emu, &fields, 125.0);
        low.input_recipes = vec![vec!["input_int_register_0".into()]];
        assert!(matches!(
            RtdeClient::connect(low).await,
            Err(RobotIoError::InputsInUse { .. })
        ));
        // Once the first writer leaves, the registers are free again.
        first.close().await;
        let mut again = client_config(&emu, &fields, 125.0);
        again.input_recipes = vec![map.input_names()];
        let mut ok = None;
        for _ in 0..100 {
            match RtdeClient::connect(again.clone()).await {
                Ok(c) => {
                    ok = Some(c);
                    break;
                }
                Err(RobotIoError::InputsInUse { .. }) => {
                    tokio::time::sleep(Duration::from_millis(20)).await
                }
                Err(e) => panic!("{e}"),
            }
        }
        assert!(ok.is_some(), "registers never released");

        // NOT_FOUND, naming the fields.
        let bad = client_config(
            &emu,
            &[
                "actual_q".into(),
                "warp_drive".into(),
                "actual_qd".into(),
                "flux".into(),
            ],
            125.0,
        );
        match RtdeClient::connect(bad).await {
            Err(RobotIoError::FieldsNotFound { fields }) => {
                assert_eq!(fields, ["warp_drive", "flux"])
            }
            other => panic!("expected FieldsNotFound, got {other:?}"),
        }

        // Refused connection.
        let port = {
            let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
            l.local_addr().unwrap().port()
        };
        let mut refused = client_config(&emu, &fields, 125.0);
        refused.port = port;
        match RtdeClient::connect(refused).await {
            Err(e @ RobotIoError::ConnectionRefused { .. }) => {
                assert!(e.to_string().contains("refused"))
            }
            other => panic!("expected ConnectionRefused, got {other:?}"),
        }

        // Controller too old.
        let robot = SimRobot::new(SimConfig::ur5e()).unwrap();
        let old = EmulatorConfig {
            controller_version: robot_io::codec::ControllerVersion {
                major: 3,
                minor: 2,
                bugfix: 0,
                build: 0,
            },
            ..EmulatorConfig::ephemeral()
        };
        let old_emu = Emulator::start(old, Box::new(SimBackend::new(robot)))
            .await
            .unwrap();
        match RtdeClient::connect(client_config(&old_emu, &fields, 125.0)).await {
            Err(RobotIoError::ControllerVersionUnsupported {
                major: 3, minor: 2, ..
            }) => {}
            other => panic!("expected ControllerVersionUnsupported, got {other:?}"),
        }
    })
    .await
    .expect("test timed out");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn protective_stop_injected_in_a_trace_is_visible_within_one_cycle() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let mut trace =
            Trace::read(data_dir().join("rtde-traces/ur3e_25hz_rad_segment_L0L1.csv")).unwrap();
        let k = trace.len() / 2;
        for row in k..trace.len() {
            trace
                .set_value(row, "safety_mode", f64::from(safety_mode::PROTECTIVE_STOP))
                .unwrap();
            trace.set_value(row, "speed_scaling", 0.0).unwrap();
        }
        let stop_t = trace.timestamp(k).unwrap();
        let cfg = EmulatorConfig {
            speedup: 2,
            ..EmulatorConfig::ephemeral()
        };
        let emu = Emulator::start(
            cfg,
            Box::new(TraceBackend::new(trace.clone(), ReplayMode::Interpolate).unwrap()),
        )
        .await
        .unwrap();
        let fields: Vec<String> = ["timestamp", "safety_mode", "speed_scaling", "actual_q"]
            .map(String::from)
            .to_vec();
        let mut client = RtdeClient::connect(client_config(&emu, &fields, 500.0))
            .await
            .unwrap();
        let mut buf = client.output_buffer();
        let (ts_slot, mode_slot) = (
            buf.slot("timestamp").unwrap(),
            buf.slot("safety_mode").unwrap(),
        );
        client.start().await.unwrap();
        let mut prev_t = f64::NEG_INFINITY;
        loop {
            let info = client.recv_timeout(&mut buf, SAMPLE_TIMEOUT).await.unwrap();
            assert_eq!(info.dropped, 0);
            let t = buf.read(ts_slot).unwrap().component(0).unwrap();
            let mode = buf.read(mode_slot).unwrap();
            if prev_t > f64::NEG_INFINITY {
                // 500 Hz: consecutive samples one 2 ms cycle apart.
                assert!(
                    (t - prev_t - 0.002).abs() < 1e-6,
                    "samples {prev_t} -> {t} not one cycle apart"
                );
            }
            if t + 1e-9 < stop_t {
                assert_eq!(
                    mode,
                    Value::Int32(safety_mode::NORMAL),
                    "stop shown early at {t}"
                );
            } else {
                // The first sample at or after the recorded stop shows it.
                assert_eq!(
                    mode,
                    Value::Int32(safety_mode::PROTECTIVE_STOP),
                    "stop not shown at {t} (stop at {stop_t})"
                );
                assert!(
                    t - stop_t < 0.002 + 1e-9,
                    "first sample after the stop came {} s late",
                    t - stop_t
                );
                break;
            }
            prev_t = t;
        }
        // The emulator's text message follows its start reply and precedes the data, so it
        // has been read once data has (checked right after `start` it raced the reader task).
        assert!(
            client
                .last_message()
                .unwrap_or_default()
                .contains("interpolate")
        );
        client.close().await;
    })
    .await
    .expect("test timed out");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_drives_the_sim_and_reports_safety() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let robot = SimRobot::new(SimConfig::ur5e()).unwrap();
        let emu = Emulator::start(
            EmulatorConfig::ephemeral(),
            Box::new(SimBackend::new(robot)),
        )
        .await
        .unwrap();
        let mut d = DashboardClient::connect(
            "127.0.0.1",
            emu.dashboard_addr().port(),
            Duration::from_secs(5),
        )
        .await
        .unwrap();
        assert!(d.is_in_remote_control().await.unwrap());
        assert_eq!(
            d.safety_status().await.unwrap(),
            SafetyStatus(safety_mode::NORMAL)
        );
        emu.with_sim(|b| b.robot_mut().inject_protective_stop())
            .unwrap();
        let mut status = SafetyStatus(0);
        for _ in 0..500 {
            status = d.safety_status().await.unwrap();
            if status.0 == safety_mode::PROTECTIVE_STOP {
                break;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        assert_eq!(status, SafetyStatus(safety_mode::PROTECTIVE_STOP));
        d.close_safety_popup().await.unwrap();
        d.unlock_protective_stop().await.unwrap();
        // Unlocking again fails: nothing to unlock.
        assert!(matches!(
            d.unlock_protective_stop().await,
            Err(RobotIoError::Dashboard { .. })
        ));
        // play without our program is refused with the controller's wording.
        assert!(matches!(
            d.play().await,
            Err(RobotIoError::Dashboard { .. })
        ));
        assert_eq!(
            d.raw("dance").await.unwrap(),
            "could not understand: 'dance'"
        );
    })
    .await
    .expect("test timed out");
}

/// Waits (bounded) until the streamed state satisfies `done`; returns that state.
async fn wait_for_state(
    robot: &mut RtdeRobot,
    what: &str,
    done: impl Fn(&RobotState) -> bool,
) -> RobotState {
    let mut s = RobotState::default();
    // 3000 samples at 125 Hz: 24 s of controller time, far beyond any transition here.
    for _ in 0..3000 {
        robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        if done(&s) {
            return s;
        }
    }
    panic!("never saw {what}; last state {s:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_power_off_power_on_and_brake_release_drive_the_sim() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let map = RegisterMap::default();
        let (emu, mut robot) = sim_setup(map, 125.0).await;
        let mut d = DashboardClient::connect(
            "127.0.0.1",
            emu.dashboard_addr().port(),
            Duration::from_secs(5),
        )
        .await
        .unwrap();
        let qd = [0.2, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut s = RobotState::default();
        for _ in 0..50 {
            robot.send(&JointCommand::Speed { qd, acc: 2.0 }).unwrap();
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        }
        assert!(s.actual_qd[0] > 0.1, "not moving: {:?}", s.actual_qd);
        assert_eq!(
            d.robot_mode().await.unwrap(),
            RobotModeReply(robot_mode::RUNNING)
        );

        // power off: the arm brakes to rest, the program stops, the mode is POWER_OFF.
        d.power_off().await.unwrap();
        let s = wait_for_state(&mut robot, "the arm powered off and at rest", |s| {
            s.robot_mode == robot_mode::POWER_OFF && s.actual_qd.iter().all(|v| *v == 0.0)
        })
        .await;
        assert_ne!(s.runtime_state, runtime_state::PLAYING);
        assert_eq!(emu.with_sim(|b| b.program_running()), Some(false));
        assert_eq!(
            d.robot_mode().await.unwrap(),
            RobotModeReply(robot_mode::POWER_OFF)
        );
        // Commands are ignored while powered off.
        let q_off = s.actual_q;
        let mut s = RobotState::default();
        for _ in 0..20 {
            robot.send(&JointCommand::Speed { qd, acc: 2.0 }).unwrap();
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        }
        assert_eq!(s.actual_q, q_off, "moved while powered off");

        // brake release needs IDLE: refused while powered off, with the controller's wording.
        let refused = d.brake_release().await;
        assert!(
            matches!(&refused, Err(RobotIoError::Dashboard { reply, .. }) if reply.starts_with("Failed to execute")),
            "{refused:?}"
        );
        // power on: POWER_OFF -> IDLE; a second power on is refused.
        d.power_on().await.unwrap();
        wait_for_state(&mut robot, "robot_mode IDLE", |s| {
            s.robot_mode == robot_mode::IDLE
        })
        .await;
        assert!(matches!(
            d.power_on().await,
            Err(RobotIoError::Dashboard { .. })
        ));
        // brake release: IDLE -> RUNNING.
        d.brake_release().await.unwrap();
        wait_for_state(&mut robot, "robot_mode RUNNING", |s| {
            s.robot_mode == robot_mode::RUNNING
        })
        .await;
        assert_eq!(
            d.robot_mode().await.unwrap(),
            RobotModeReply(robot_mode::RUNNING)
        );

        // Our program runs again once re-sent, and the arm moves.
        ScriptSender::new("127.0.0.1", emu.secondary_addr().port())
            .send_control_program(&map)
            .await
            .unwrap();
        wait_for_state(&mut robot, "the program playing again", |s| {
            s.runtime_state == runtime_state::PLAYING
        })
        .await;
        let mut s = RobotState::default();
        for _ in 0..50 {
            robot.send(&JointCommand::Speed { qd, acc: 2.0 }).unwrap();
            robot.wait_state(&mut s, SAMPLE_TIMEOUT).await.unwrap();
        }
        assert!(s.actual_qd[0] > 0.1, "not moving after power-up: {:?}", s.actual_qd);
    })
    .await
    .expect("test timed out");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn emulator_drops_a_client_that_stops_reading() {
    use robot_io::codec::ClientPackage;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    tokio::time::timeout(TEST_TIMEOUT, async {
        let robot = SimRobot::new(SimConfig::ur5e()).unwrap();
        let cfg = EmulatorConfig {
            speedup: 20,
            stall_timeout: Duration::from_millis(300),
            queue_packages: 20,
            ..EmulatorConfig::ephemeral()
        };
        let emu = Emulator::start(cfg, Box::new(SimBackend::new(robot)))
            .await
            .unwrap();
        // A hand-rolled client: set up a large recipe, start, then never read again. A small
        // receive buffer makes the stall show within a few packages, whatever the kernel's
        // autotuned loopback buffers and however slowly a loaded machine runs the emulator.
        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        socket.set_recv_buffer_size(4096).unwrap();
        let mut s = socket.connect(emu.rtde_addr()).await.unwrap();
        let names = [
            "actual_q",
            "actual_qd",
            "target_q",
            "target_qd",
            "actual_TCP_pose",
            "actual_TCP_speed",
        ]
        .repeat(8)
        .join(",");
        let mut out = Vec::new();
        ClientPackage::RequestProtocolVersion { version: 2 }
            .encode(&mut out)
            .unwrap();
        ClientPackage::SetupOutputs {
            frequency_hz: 500.0,
            names: &names,
        }
        .encode(&mut out)
        .unwrap();
        ClientPackage::Start.encode(&mut out).unwrap();
        s.write_all(&out).await.unwrap();
        let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
        // First the session must exist (the emulator accepts asynchronously: checking for 0
        // before it registers would pass at once and leave the read loop below on a live
        // stream), then it must be dropped.
        while emu.rtde_sessions() == 0 {
            assert!(
                tokio::time::Instant::now() < deadline,
                "the session never started"
            );
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        while emu.rtde_sessions() > 0 {
            assert!(
                tokio::time::Instant::now() < deadline,
                "the stalled client was never dropped"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        // Reading now drains what was buffered and then hits the closed connection.
        let mut sink = vec![0u8; 1 << 16];
        let mut total = 0usize;
        loop {
            match tokio::time::timeout(Duration::from_secs(10), s.read(&mut sink)).await {
                Ok(Ok(0)) | Ok(Err(_)) => break,
                Ok(Ok(n)) => total += n,
                Err(_) => panic!("connection still open after the drop"),
            }
        }
        assert!(total > 0);
    })
    .await
    .expect("test timed out");
}
