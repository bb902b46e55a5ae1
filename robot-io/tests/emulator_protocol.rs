//! The emulator's RTDE and dashboard protocols as a client we did not write sees them (issue
//! 11): raw packages over loopback TCP to an in-process [`Emulator`], encoded and decoded with
//! robot-io's codec, and dashboard lines by hand, so nothing of our own client's behaviour hides a server defect.
//!
//! No assertion depends on wall-clock speed: waits are bounded by generous timeouts only.

mod common;

use std::time::Duration;

use common::{REPLY_TIMEOUT, Raw, TEST_TIMEOUT, sim_emulator};
use robot_io::codec::{ClientPackage, ControllerPackage, DataPackage, FieldType, Value};
use robot_io::emulator::{
    ClockStats, Emulator, EmulatorConfig, MAX_DASHBOARD_LINE, ReplayMode, SLEW_RATE, Slew,
    TickPlan, TraceBackend, clock_on_own_thread, max_cycles_per_wake, plan_ticks, slew_window,
};
use robot_io::trace::Trace;
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::TcpStream;

/// A trailing comma (as ur_rtde ends every list) is ignored: the output recipe is accepted
/// with one type per real name, and so is an input recipe; an unknown name in such a list is
/// still answered `NOT_FOUND` (for that name only) and refuses the recipe.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_trailing_comma_is_ignored_and_unknown_names_are_still_not_found() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let emu = sim_emulator(EmulatorConfig::ephemeral()).await;
        let mut c = Raw::connect(&emu).await;
        c.handshake().await;

        let (id, types) = c
            .setup_outputs(125.0, "timestamp,actual_q,robot_mode,")
            .await;
        assert_eq!(types, "DOUBLE,VECTOR6D,INT32");
        assert_ne!(id, 0, "a list with a trailing comma was refused");

        let (id, types) = c.setup_outputs(125.0, "timestamp,no_such_field,").await;
        assert_eq!(types, "DOUBLE,NOT_FOUND");
        assert_eq!(id, 0);

        let (id, types) = c
            .setup_inputs("input_int_register_24,input_double_register_24,")
            .await;
        assert_eq!(types, "INT32,DOUBLE");
        assert_ne!(id, 0, "an input list with a trailing comma was refused");

        let (id, types) = c.setup_inputs("input_int_register_25,bogus,").await;
        assert_eq!(types, "INT32,NOT_FOUND");
        assert_eq!(id, 0);

        // The accepted output recipe streams with the three fields' sizes.
        c.send(ClientPackage::Start).await;
        assert_eq!(
            c.recv_non_text().await,
            ControllerPackage::StartAccepted(true)
        );
        match c.recv_non_text().await {
            ControllerPackage::Data(d) => assert_eq!(d.payload.len(), 8 + 48 + 4),
            other => panic!("expected data, got {other:?}"),
        }
    })
    .await
    .expect("test timed out");
}

/// Output and input recipe ids are numbered separately, each from 1, as a controller numbers
/// them: after one output recipe (id 1) the first input recipe is 1 and the second 2; a
/// refused recipe answers id 0 and consumes no id; the second output recipe is 2. Inputs
/// written to input recipe 1 and 2 reach their registers (echoed in the outputs).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn input_and_output_recipe_ids_are_numbered_separately_from_one() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let emu = sim_emulator(EmulatorConfig::ephemeral()).await;
        let mut c = Raw::connect(&emu).await;
        c.handshake().await;

        let (id, _) = c.setup_outputs(125.0, "timestamp").await;
        assert_eq!(id, 1, "first output recipe");
        let (id, types) = c.setup_inputs("input_int_register_24").await;
        assert_eq!((id, types.as_str()), (1, "INT32"), "first input recipe");
        let (id, types) = c.setup_inputs("input_int_register_25,no_such_input").await;
        assert_eq!((id, types.as_str()), (0, "INT32,NOT_FOUND"), "refused");
        let (id, types) = c.setup_inputs("input_double_register_24").await;
        assert_eq!((id, types.as_str()), (2, "DOUBLE"), "second input recipe");
        let (id, _) = c.setup_outputs(125.0, "nope").await;
        assert_eq!(id, 0, "refused output recipe");
        let (id, types) = c
            .setup_outputs(125.0, "input_int_register_24,input_double_register_24")
            .await;
        assert_eq!(
            (id, types.as_str()),
            (2, "INT32,DOUBLE"),
            "second output recipe"
        );

        // Each input recipe id addresses its own registers.
        let mut payload = Vec::new();
        Value::Int32(7).encode(&mut payload);
        c.send(ClientPackage::Data(DataPackage {
            recipe_id: 1,
            payload: &payload,
        }))
        .await;
        payload.clear();
        Value::Double(2.5).encode(&mut payload);
        c.send(ClientPackage::Data(DataPackage {
            recipe_id: 2,
            payload: &payload,
        }))
        .await;
        c.send(ClientPackage::Start).await;
        assert_eq!(
            c.recv_non_text().await,
            ControllerPackage::StartAccepted(true)
        );
        loop {
            let ControllerPackage::Data(d) = c.recv_non_text().await else {
                panic!("expected data");
            };
            // Both output recipes stream (several on one connection); recipe 2 echoes.
            assert!([1, 2].contains(&d.recipe_id), "recipe {}", d.recipe_id);
            if d.recipe_id == 1 {
                assert_eq!(d.payload.len(), 8, "recipe 1 is the timestamp");
                continue;
            }
            let int = Value::decode(FieldType::Int32, d.payload, 0).unwrap();
            let double = Value::decode(FieldType::Double, d.payload, 4).unwrap();
            if (int, double) == (Value::Int32(7), Value::Double(2.5)) {
                break;
            }
        }
    })
    .await
    .expect("test timed out");
}

/// A 500 Hz trace of `rows` rows: timestamp 10 s + k · 2 ms, `speed_scaling` = k (so each
/// package names the row it came from).
fn numbered_trace(rows: usize) -> Trace {
    let mut trace = Trace::new(["timestamp", "speed_scaling"]).unwrap();
    for k in 0..rows {
        trace
            .push_row(&[10.0 + k as f64 * 0.002, k as f64])
            .unwrap();
    }
    trace
}

/// Trace replay sends the first row: a client streaming a 500 Hz trace at 500 Hz receives
/// rows 0, 1, 2, … in order (it used to start at row 1): bit for bit when holding; when
/// interpolating, the first row bit for bit and the rest up to float rounding.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn trace_replay_sends_the_first_row_first() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let trace = numbered_trace(50);
        for mode in [ReplayMode::Hold, ReplayMode::Interpolate] {
            let backend = TraceBackend::new(trace.clone(), mode).unwrap();
            let emu = Emulator::start(EmulatorConfig::ephemeral(), Box::new(backend))
                .await
                .unwrap();
            let mut c = Raw::connect(&emu).await;
            c.handshake().await;
            let (id, types) = c.setup_outputs(500.0, "timestamp,speed_scaling,").await;
            assert_eq!((id, types.as_str()), (1, "DOUBLE,DOUBLE"));
            c.send(ClientPackage::Start).await;
            assert_eq!(
                c.recv_non_text().await,
                ControllerPackage::StartAccepted(true)
            );
            for k in 0..10 {
                let ControllerPackage::Data(d) = c.recv_non_text().await else {
                    panic!("expected data");
                };
                let ts = Value::decode(FieldType::Double, d.payload, 0).unwrap();
                let row = Value::decode(FieldType::Double, d.payload, 8).unwrap();
                let expected = (
                    Value::Double(trace.timestamp(k).unwrap()),
                    Value::Double(k as f64),
                );
                if mode == ReplayMode::Hold || k == 0 {
                    assert_eq!((ts, row), expected, "{mode:?}: package {k}");
                } else {
                    // Interpolation runs on the virtual clock (a sum of 2 ms steps): equal
                    // up to float rounding.
                    let near = |a: Value, b: Value| {
                        (a.component(0).unwrap() - b.component(0).unwrap()).abs() < 1e-9
                    };
                    assert!(
                        near(ts, expected.0) && near(row, expected.1),
                        "{mode:?}: package {k}: {ts:?}, {row:?}"
                    );
                }
            }
        }
    })
    .await
    .expect("test timed out");
}

/// The clock's per-wake schedule (in controller cycles), with exact numbers: on time one
/// cycle runs; after missed cycles without a slew allowance the backlog runs (all but the
/// newest late); beyond the bound the excess is dropped, never deferred; nothing is due,
/// nothing runs. With an allowance that much of the backlog stays behind, but a due cycle
/// always runs. `done + run + dropped + behind == due` throughout.
#[test]
fn the_clock_catches_up_missed_ticks_within_the_bound_and_counts_the_rest_dropped() {
    let plan = |run, late, dropped, behind| TickPlan {
        run,
        late,
        dropped,
        behind,
    };
    // (due, done, max per wake, allowance) → (run, late, dropped, behind).
    for ((due, done, max, allowance), (run, late, dropped, behind), why) in [
        ((1, 0, 50, 0), (1, 0, 0, 0), "on time"),
        ((10, 10, 50, 0), (0, 0, 0, 0), "nothing due"),
        ((17, 10, 50, 0), (7, 6, 0, 0), "caught up"),
        ((60, 10, 50, 0), (50, 49, 0, 0), "exactly the bound"),
        ((1010, 10, 50, 0), (50, 49, 950, 0), "a 2 s stall"),
        ((5, 3, 0, 0), (1, 0, 1, 0), "a bound of 0 counts as 1"),
        ((3, 5, 50, 0), (0, 0, 0, 0), "done ahead of due"),
        // Slewing: 7 due, 6 of them may stay behind: one runs.
        ((17, 10, 50, 6), (1, 0, 0, 6), "slewed"),
        ((17, 10, 50, 40), (1, 0, 0, 6), "allowance > backlog"),
        ((17, 10, 50, 4), (3, 2, 0, 4), "backlog > allowance"),
        ((10, 10, 50, 4), (0, 0, 0, 0), "slewing, nothing due"),
        (
            (1010, 10, 50, 40),
            (50, 49, 910, 40),
            "a 2 s stall keeps 40 to slew",
        ),
    ] {
        assert_eq!(
            plan_ticks(due, done, max, allowance),
            plan(run, late, dropped, behind),
            "{why}"
        );
    }
    for (due, done) in [(0, 0), (1, 0), (17, 10), (1010, 10), (u64::MAX, 0)] {
        for allowance in [0, 1, 6, 40, u64::MAX] {
            let p = plan_ticks(due, done, 50, allowance);
            assert_eq!(
                done + p.run + p.dropped + p.behind,
                due,
                "due {due}, done {done}, allowance {allowance}"
            );
            assert_eq!(p.run >= 1, due > done, "a due cycle runs");
        }
    }
    // The bound: the cycles of 100 ms of wall time (50 × speedup), and at most 1000.
    assert_eq!(max_cycles_per_wake(0), 50, "speedup 0 counts as 1");
    assert_eq!(max_cycles_per_wake(1), 50);
    assert_eq!(max_cycles_per_wake(4), 200);
    assert_eq!(max_cycles_per_wake(20), 1000);
    assert_eq!(max_cycles_per_wake(100), 1000);
    assert_eq!(max_cycles_per_wake(u32::MAX), 1000);
    // Cycle periods of 2 ms and 1 ms sleep on tokio's 1 ms timer; shorter ones (0.67 ms at
    // speedup 3) on the clock's own thread.
    assert!(!clock_on_own_thread(1));
    assert!(!clock_on_own_thread(2));
    assert!(clock_on_own_thread(3));
    assert!(clock_on_own_thread(4));
    assert!(clock_on_own_thread(100));
}

/// The clock's slew, worked by hand (cycles elapsed by wall time are fractional, SLEW_RATE
/// 0.25, window 40): on time nothing lags and the next cycle is due at its own time. A wake at
/// 17.5 with 10 cycles done finds 7 due: one runs now and the other 6 become the lag. Cycle 12
/// is then due where v − lag(v) = 12, lag(v) = 6 − 0.25·(v − 17.5): v = (12 + 6 + 0.25·17.5) /
/// 1.25 = 17.9 (lag 5.9, so allowance 5 there, and one cycle runs). Woken at each such time
/// the clock runs exactly one cycle per wake, 0.8 of a period apart; nothing is left behind
/// once the lag is under one cycle, from 17.5 + 5 / 0.25 = 37.5 on (the wake at 37.9), and
/// the lag has run out at 17.5 + 6 / 0.25 = 41.5 (the last early wake at (41 + 10.375) /
/// 1.25 = 41.1, then cycle 42 at its own time). A backlog beyond the window keeps only the
/// window.
#[test]
fn the_clock_slews_a_backlog_one_cycle_per_wake_at_a_quarter_over_its_rate() {
    assert_eq!(SLEW_RATE, 0.25);
    assert_eq!(slew_window(1), 10);
    assert_eq!(slew_window(4), 40);
    assert_eq!(slew_window(0), 10, "speedup 0 counts as 1");
    let mut s = Slew::default();
    assert_eq!(s.on_wake(10.3, 10, 40), 0, "on time");
    assert_eq!(s.next_due(10), 11.0);
    assert_eq!(s.on_wake(17.5, 10, 40), 6, "a stall of 7 cycles");
    assert_eq!(s.lag(17.5), 6.0);
    assert_eq!(plan_ticks(17, 10, 50, 6).run, 1);
    assert!((s.next_due(11) - 17.9).abs() < 1e-12, "{}", s.next_due(11));
    assert!((s.lag(17.9) - 5.9).abs() < 1e-12);
    assert_eq!(s.on_wake(17.9, 11, 40), 5, "within the lag: no new stall");
    let (mut done, mut prev) = (12, 17.9);
    let mut caught_up = None;
    loop {
        let v = s.next_due(done);
        if v > 41.5 {
            break;
        }
        assert!(
            (v - prev - 0.8).abs() < 1e-9,
            "0.8 periods apart: {prev} → {v}"
        );
        let allowance = s.on_wake(v + 1e-9, done, 40);
        let p = plan_ticks(v.floor() as u64, done, 50, allowance);
        assert_eq!((p.run, p.dropped), (1, 0), "one cycle per wake at {v}");
        done = v.floor() as u64 - p.behind;
        if p.behind == 0 && caught_up.is_none() {
            caught_up = Some(v);
        }
        prev = v;
    }
    let caught_up = caught_up.expect("caught up");
    assert!(
        (caught_up - 37.9).abs() < 1e-9,
        "nothing behind from {caught_up}"
    );
    assert!((prev - 41.1).abs() < 1e-9, "last early wake at {prev}");
    assert_eq!(done, 41, "back on wall time");
    assert_eq!(s.next_due(done), 42.0, "and on its own period again");
    // Beyond the window: only the window stays behind; reset drops the lag.
    assert_eq!(s.on_wake(200.0, 41, 40), 40);
    assert_eq!(plan_ticks(200, 41, 200, 40).behind, 40);
    s.reset();
    assert_eq!(s.lag(200.0), 0.0);
}

/// Checks the clock invariants of [`ClockStats`] on `s`.
fn consistent(s: ClockStats) -> ClockStats {
    assert_eq!(
        s.cycles_run + s.cycles_dropped + s.cycles_paused + s.cycles_waited + s.cycles_behind,
        s.cycles_elapsed,
        "{s:?}"
    );
    assert!(s.cycles_late <= s.cycles_run, "{s:?}");
    assert!(s.cycles_slewed <= s.cycles_run, "{s:?}");
    // A burst holds the emulator's state: no command arrives within it, so at most one hold
    // begins in it.
    assert!(s.holds_in_bursts <= s.bursts, "{s:?}");
    assert!(s.cycles_behind <= slew_window(100), "{s:?}");
    s
}

/// Polls the clock (every millisecond) until `cond` holds, checking its invariants at every
/// read; the caller's timeout bounds it.
async fn clock_until(emu: &Emulator, cond: impl Fn(ClockStats) -> bool) -> ClockStats {
    loop {
        let s = consistent(emu.clock_stats());
        if cond(s) {
            return s;
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
}

/// The emulator's clock counters stay consistent through a pause: at every read, cycles run
/// + dropped + paused is exactly the cycles due by wall time × speedup; while paused no
/// cycle runs and the skipped cycles count as paused (not late, not dropped); after resuming
/// cycles run again and nothing more counts as paused. No wall-clock threshold is asserted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clock_counters_are_consistent_through_pause_and_resume() {
    const SPEEDUP: u64 = 3;
    tokio::time::timeout(TEST_TIMEOUT, async {
        let emu = sim_emulator(EmulatorConfig {
            speedup: SPEEDUP as u32,
            ..EmulatorConfig::ephemeral()
        })
        .await;
        let running = clock_until(&emu, |s| s.cycles_run > 0).await;
        assert_eq!(running.cycles_paused, 0);
        assert!(emu.cycle() >= running.cycles_run);

        emu.pause();
        let first = clock_until(&emu, |s| s.cycles_paused > 0).await;
        let later = clock_until(&emu, |s| s.cycles_paused > first.cycles_paused).await;
        assert_eq!(
            later.cycles_run, first.cycles_run,
            "a cycle ran while paused"
        );
        assert_eq!(emu.cycle(), later.cycles_run);

        emu.resume();
        let resumed = clock_until(&emu, |s| s.cycles_run > later.cycles_run).await;
        let after = clock_until(&emu, |s| s.cycles_run > resumed.cycles_run).await;
        assert_eq!(
            after.cycles_paused, resumed.cycles_paused,
            "cycles counted as paused after resuming"
        );
        assert!(emu.cycle() >= after.cycles_run);
    })
    .await
    .expect("test timed out");
}

/// A dashboard connection: the greeting read, then one line per reply.
struct Dash {
    r: BufReader<tokio::net::tcp::OwnedReadHalf>,
    w: tokio::net::tcp::OwnedWriteHalf,
}

impl Dash {
    async fn connect(emu: &Emulator) -> Dash {
        let (r, w) = TcpStream::connect(emu.dashboard_addr())
            .await
            .unwrap()
            .into_split();
        let mut d = Dash {
            r: BufReader::new(r),
            w,
        };
        assert_eq!(
            d.line().await,
            "Connected: Universal Robots Dashboard Server"
        );
        d
    }

    async fn line(&mut self) -> String {
        let mut s = String::new();
        let n = tokio::time::timeout(REPLY_TIMEOUT, self.r.read_line(&mut s))
            .await
            .expect("no dashboard reply")
            .unwrap();
        assert!(n > 0, "the dashboard closed the connection");
        s.trim_end_matches('\n').to_owned()
    }

    async fn send(&mut self, bytes: &[u8]) {
        self.w.write_all(bytes).await.unwrap();
    }
}

/// The dashboard bounds a line at 4096 bytes: a 4096-byte unknown command is answered as
/// unknown (echoed whole); 1 MiB without a newline is answered once, as soon as it overflows,
/// with an error line, and the rest of it up to its newline is discarded, so the next command
/// on the same connection (and on a new one) is answered normally. Memory cannot be measured
/// here: the bound shows in the reply (an unbounded reader would only answer at the newline,
/// after buffering the whole MiB, and would then echo it).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_bounds_a_line_and_discards_the_rest_of_an_overlong_one() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let emu = sim_emulator(EmulatorConfig::ephemeral()).await;
        assert_eq!(MAX_DASHBOARD_LINE, 4096);
        let mut d = Dash::connect(&emu).await;

        let at_bound = "x".repeat(MAX_DASHBOARD_LINE);
        d.send(format!("{at_bound}\n").as_bytes()).await;
        assert_eq!(
            d.line().await,
            format!("could not understand: '{at_bound}'")
        );

        d.send(&vec![b'a'; 1 << 20]).await;
        // Answered before the newline is sent.
        assert_eq!(
            d.line().await,
            "could not understand: line longer than 4096 bytes (discarded)"
        );
        d.send(b"aaaa\nrobotmode\n").await;
        let reply = d.line().await;
        assert!(reply.starts_with("Robotmode: "), "{reply}");
        d.send(b"is in remote control\r\n").await;
        assert_eq!(d.line().await, "true");

        let mut fresh = Dash::connect(&emu).await;
        fresh.send(b"robotmode\n").await;
        let reply = fresh.line().await;
        assert!(reply.starts_with("Robotmode: "), "{reply}");
    })
    .await
    .expect("test timed out");
}

/// A trace replay serves an output register the trace did not record as 0, as a controller
/// serves a register nothing writes (`RtdeRobot` subscribes to our program's tick register),
/// while any other unrecorded field stays NOT_FOUND and recorded ones are replayed.
#[test]
fn trace_replay_serves_unrecorded_output_registers_as_zero_and_nothing_else() {
    use robot_io::emulator::EmulatorBackend;
    let mut b = TraceBackend::new(numbered_trace(5), ReplayMode::Hold).unwrap();
    for (name, ty) in [
        ("output_int_register_24", FieldType::Int32),
        ("output_double_register_3", FieldType::Double),
        ("output_bit_registers0_to_31", FieldType::Uint32),
    ] {
        let (h, got) = b.output_handle(name).expect(name);
        assert_eq!(got, ty, "{name}");
        assert_eq!(b.read_output(h), Value::zero(ty), "{name}");
    }
    assert!(
        b.output_handle("actual_q").is_none(),
        "actual_q is not in the trace"
    );
    assert!(b.output_handle("input_int_register_24").is_none());
    assert!(b.output_handle("no_such_field").is_none());
    let (h, _) = b.output_handle("speed_scaling").unwrap();
    assert_eq!(b.read_output(h), Value::Double(0.0)); // row 0 records k = 0
    let (h, _) = b.output_handle("timestamp").unwrap();
    assert_eq!(b.read_output(h), Value::Double(10.0));
}
