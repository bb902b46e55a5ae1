//! SimRobot → trace file → Trace/ReplayRobot, end to end (all data here is simulated).
//!
//! A recorder that samples the published state once per cycle sees an injected dropped-cycle
//! stretch exactly as an asynchronous ur_rtde recording does: repeated timestamps, then a jump.

use robot_io::replay::ReplayRobot;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::trace::{
    Dialect, FloatFormat, STATE_FIELD_NAMES, Trace, TraceWriter, WriteOptions, state_to_row,
};
use robot_io::{JointCommand, Robot, RobotIoError, RobotState};

/// Run a simulated trial, recording the published state every cycle. Returns the states as
/// recorded (duplicates included) and the file text.
fn record(options: &WriteOptions) -> (Vec<RobotState>, String) {
    let mut robot = SimRobot::new(SimConfig::ur5e()).unwrap();
    let mut writer = TraceWriter::new(Vec::new(), &STATE_FIELD_NAMES, options).unwrap();
    let mut states = Vec::new();
    let mut state = RobotState::default();
    let mut row = [0.0; 44];
    for cycle in 0..1000 {
        match cycle {
            0 => robot
                .send(&JointCommand::Speed {
                    qd: [0.3, -0.2, 0.1, 0.0, 0.0, 0.4],
                    acc: 1.0,
                })
                .unwrap(),
            300 => robot.inject_dropped_cycles(4),
            600 => robot.inject_dropped_cycles(1),
            700 => robot.inject_protective_stop(),
            _ => {}
        }
        robot.step();
        robot.read_state(&mut state).unwrap();
        state_to_row(&state, &mut row);
        writer.write_row(&row).unwrap();
        states.push(state);
    }
    let text = String::from_utf8(writer.into_inner()).unwrap();
    (states, text)
}

#[test]
fn dropped_cycles_show_up_as_duplicates_and_gaps_in_a_recording() {
    let (states, text) = record(&WriteOptions::ur_rtde());
    let trace = Trace::parse(&text, "simulated.csv").unwrap();
    let report = trace.report();
    assert_eq!(report.duplicates_removed, 5);
    assert_eq!(trace.len(), 995);
    assert!((report.nominal_period_s.unwrap() - 0.002).abs() < 1e-9);
    let gaps: Vec<(f64, u64)> = report
        .gaps
        .iter()
        .map(|g| (g.after_timestamp, g.missing_periods))
        .collect();
    // Injected before step 301 (timestamp 0.602): the last published sample before the freeze
    // is cycle 300 (0.600 s); 4 cycles are never published.
    assert_eq!(gaps.len(), 2, "{gaps:?}");
    assert!(
        (gaps[0].0 - 0.600).abs() < 1e-9 && gaps[0].1 == 4,
        "{gaps:?}"
    );
    assert!(
        (gaps[1].0 - 1.200).abs() < 1e-9 && gaps[1].1 == 1,
        "{gaps:?}"
    );

    // Replaying gives back the distinct recorded states, bit for bit.
    let mut distinct = states.clone();
    distinct.dedup_by(|b, a| a.timestamp_s == b.timestamp_s);
    let mut replay = ReplayRobot::new(trace);
    let mut out = RobotState::default();
    for expected in &distinct {
        replay.read_state(&mut out).unwrap();
        assert_eq!(&out, expected);
    }
    assert!(matches!(
        replay.read_state(&mut out),
        Err(RobotIoError::TraceEnded { rows: 995 })
    ));
    // The injected protective stop is in the recording.
    assert!(out.is_safety_stopped());
    assert_eq!(out.actual_qd, [0.0; 6]);
}

#[test]
fn ur_rtde_six_decimal_recordings_read_back_within_their_precision() {
    let options = WriteOptions {
        dialect: Dialect::Comma,
        float_format: FloatFormat::Fixed(6),
    };
    let (states, text) = record(&options);
    let first_data_line = text.lines().nth(1).unwrap();
    assert!(
        first_data_line.starts_with("0.002000,"),
        "{first_data_line}"
    );
    let trace = Trace::parse(&text, "simulated_fixed6.csv").unwrap();
    assert_eq!(trace.report().duplicates_removed, 5);
    let mut out = RobotState::default();
    trace.fill_state(0, &mut out).unwrap();
    for (a, b) in out.actual_q.iter().zip(&states[0].actual_q) {
        assert!((a - b).abs() <= 5e-7);
    }
    assert_eq!(out.runtime_state, states[0].runtime_state);
}

#[test]
fn record_py_dialect_round_trips_a_simulated_run() {
    let (states, text) = record(&WriteOptions::record_py());
    assert!(text.starts_with("timestamp target_q_0 "));
    let trace = Trace::parse(&text, "simulated_recordpy.csv").unwrap();
    assert_eq!(trace.dialect(), Dialect::Space);
    let mut out = RobotState::default();
    trace.fill_state(trace.len() - 1, &mut out).unwrap();
    assert_eq!(&out, states.last().unwrap());
}
