//! Handover task state machine: happy path, timeout, attention gating, C/G truth table, grasp
//! timing, events and config validation. Time is injected; the "robot" here is a stand-in that
//! arrives at each target a fixed time after the target changes.

use adapt::AdaptError;
use adapt::task::{
    EventBuffer, HandoverTask, Phase, RawPose, RawPoses, RawTaskConfig, TaskConfig, TaskEventKind,
    TaskInput,
};

const DT: f64 = 0.002;
/// How long the stand-in robot takes to reach a new target [s].
const TRAVEL_S: f64 = 1.0;

/// A stand-in world: the TCP sits at a fixed point per target; motion finishes `TRAVEL_S` after
/// the target changes.
struct World {
    task: HandoverTask,
    events: EventBuffer<64>,
    now: f64,
    target_since: f64,
    last_target: Option<[f64; 6]>,
    wait_for_attention: bool,
    attention: bool,
    start_delay_s: f64,
    present_timeout_s: Option<f64>,
    hands: [Option<[f64; 3]>; 2],
    /// Phases seen, in order, without repeats.
    trace: Vec<Phase>,
}

/// Where the stand-in TCP is at the handover pose [m].
const HANDOVER_TCP: [f64; 3] = [0.6, 0.2, 0.4];

impl World {
    fn new(cfg: TaskConfig) -> World {
        let task = HandoverTask::try_new(cfg).unwrap();
        World {
            trace: vec![task.phase()],
            task,
            events: EventBuffer::new(),
            now: 0.0,
            target_since: 0.0,
            last_target: None,
            wait_for_attention: false,
            attention: false,
            start_delay_s: 0.0,
            present_timeout_s: None,
            hands: [None, None],
        }
    }

    fn tick(&mut self) {
        let target = self.task.target_q_rad().copied();
        if target != self.last_target {
            self.last_target = target;
            self.target_since = self.now;
        }
        let input = TaskInput {
            now_s: self.now,
            tcp_position_m: HANDOVER_TCP,
            motion_finished: target.is_some() && self.now - self.target_since >= TRAVEL_S,
            hands_m: self.hands,
            wait_for_attention: self.wait_for_attention,
            attention_on_robot: self.attention,
            start_delay_s: self.start_delay_s,
            present_timeout_s: self.present_timeout_s,
        };
        self.task.step(&input, &mut self.events);
        if self.trace.last() != Some(&self.task.phase()) {
            self.trace.push(self.task.phase());
        }
        self.now += DT;
    }

    fn run_until(&mut self, phase: Phase, max_s: f64) {
        let end = self.now + max_s;
        while self.task.phase() != phase {
            assert!(
                self.now < end,
                "did not reach {phase} within {max_s} s: {:?}",
                self.trace
            );
            self.tick();
        }
    }

    fn run_for(&mut self, s: f64) {
        let end = self.now + s;
        while self.now < end {
            self.tick();
        }
    }

    fn kinds(&self) -> Vec<TaskEventKind> {
        self.events.iter().map(|e| e.kind).collect()
    }

    fn event_time(&self, kind: TaskEventKind) -> f64 {
        self.events
            .iter()
            .find(|e| e.kind == kind)
            .unwrap_or_else(|| panic!("no {kind:?} in {:?}", self.kinds()))
            .t_s
    }
}

fn cfg() -> TaskConfig {
    TaskConfig::example()
}

#[test]
fn happy_path_reaches_done_with_release_confirmed() {
    let c = cfg();
    let mut w = World::new(c);
    w.run_for(0.1);
    assert_eq!(w.task.phase(), Phase::Idle, "idle until started");
    w.task.start();
    w.run_until(Phase::Present, 10.0);
    // The operator's right hand comes to the TCP and stays.
    w.hands = [
        None,
        Some([HANDOVER_TCP[0] + 0.03, HANDOVER_TCP[1], HANDOVER_TCP[2]]),
    ];
    let hand_in = w.now;
    w.run_until(Phase::Done, 10.0);

    assert_eq!(
        w.trace,
        [
            Phase::Idle,
            Phase::Fetch,
            Phase::Approach,
            Phase::Present,
            Phase::Release,
            Phase::Retreat,
            Phase::Done
        ]
    );
    assert!(
        !w.task.incomplete(),
        "G(t) false once the release is confirmed"
    );
    assert!(!w.task.part_returned());
    let grasp = w.event_time(TaskEventKind::GraspDetected { hand: 1 });
    assert!(
        grasp - hand_in >= c.grasp_time_s - 1e-9,
        "grasp after the full t_grasp"
    );
    assert!(grasp - hand_in < c.grasp_time_s + 2.0 * DT);
    let release = w.event_time(TaskEventKind::ReleaseConfirmed);
    assert!((release - grasp - c.release_dwell_s).abs() < 2.0 * DT);
    let gripped = w.event_time(TaskEventKind::PartGripped);
    let fetch = w.event_time(TaskEventKind::PhaseChanged {
        from: Phase::Idle,
        to: Phase::Fetch,
    });
    assert!((gripped - fetch - TRAVEL_S - c.grip_dwell_s).abs() < 2.0 * DT);
    // Events are in time order and there is exactly one event per phase change.
    let times: Vec<f64> = w.events.iter().map(|e| e.t_s).collect();
    assert!(times.windows(2).all(|p| p[0] <= p[1]));
    let changes = w
        .kinds()
        .iter()
        .filter(|k| matches!(k, TaskEventKind::PhaseChanged { .. }))
        .count();
    assert_eq!(changes, w.trace.len() - 1);
    assert_eq!(w.events.dropped(), 0);
    // Retreat went home.
    assert_eq!(w.task.target_q_rad(), None, "done: hold");
}

#[test]
fn timeout_returns_the_part_without_release() {
    let c = cfg();
    let mut w = World::new(c);
    w.task.start();
    w.run_until(Phase::Present, 10.0);
    let present_at = w.now - DT;
    w.run_until(Phase::Retreat, c.present_timeout_s + 1.0);
    let t = w.event_time(TaskEventKind::PresentTimeout);
    assert!((t - present_at - c.present_timeout_s).abs() < 2.0 * DT);
    assert!(w.task.part_returned());
    assert_eq!(
        w.task.target_q_rad(),
        Some(&c.pick_q_rad),
        "the part goes back to the pick pose"
    );
    w.run_until(Phase::Done, 10.0);
    assert!(!w.trace.contains(&Phase::Release));
    assert!(
        w.task.incomplete(),
        "G(t) stays true: the release never happened"
    );
    assert!(!w.kinds().contains(&TaskEventKind::ReleaseConfirmed));
}

#[test]
fn the_adaptations_present_timeout_is_taken_when_the_presentation_starts() {
    let c = cfg();
    // 3 s instead of the config's: the part goes back 3 s after it is presented, and a change
    // during the presentation does not move that time.
    let mut w = World::new(c);
    w.present_timeout_s = Some(3.0);
    w.task.start();
    w.run_until(Phase::Present, 10.0);
    let present_at = w.now - DT;
    w.present_timeout_s = Some(100.0);
    w.run_until(Phase::Retreat, 4.0);
    let t = w.event_time(TaskEventKind::PresentTimeout);
    assert!(
        (t - present_at - 3.0).abs() < 2.0 * DT,
        "{}",
        t - present_at
    );
    assert!(w.task.part_returned());
    // A timeout no grasp fits in (not above grasp_time_s), or not finite: the config's.
    for bad in [c.grasp_time_s, 0.0, f64::NAN, f64::INFINITY] {
        let mut w = World::new(c);
        w.present_timeout_s = Some(bad);
        w.task.start();
        w.run_until(Phase::Present, 10.0);
        let present_at = w.now - DT;
        w.run_until(Phase::Retreat, c.present_timeout_s + 1.0);
        let t = w.event_time(TaskEventKind::PresentTimeout);
        assert!(
            (t - present_at - c.present_timeout_s).abs() < 2.0 * DT,
            "{bad}: {}",
            t - present_at
        );
    }
}

#[test]
fn wait_for_attention_gates_the_approach() {
    let mut w = World::new(cfg());
    w.wait_for_attention = true;
    w.attention = false;
    w.task.start();
    w.run_until(Phase::WaitForAttention, 10.0);
    assert_eq!(
        w.task.target_q_rad(),
        Some(&cfg().pick_q_rad),
        "holds at the pick pose"
    );
    w.run_for(5.0);
    assert_eq!(
        w.task.phase(),
        Phase::WaitForAttention,
        "no approach without attention"
    );
    assert!(!w.task.collaborating());
    w.attention = true;
    let looked = w.now;
    w.tick();
    assert_eq!(w.task.phase(), Phase::Approach);
    let t = w.event_time(TaskEventKind::PhaseChanged {
        from: Phase::WaitForAttention,
        to: Phase::Approach,
    });
    assert!((t - looked).abs() < 1e-12);
}

#[test]
fn no_wait_when_not_asked_or_attention_already_there() {
    for (wait, attention) in [(false, false), (true, true)] {
        let mut w = World::new(cfg());
        w.wait_for_attention = wait;
        w.attention = attention;
        w.task.start();
        w.run_until(Phase::Approach, 10.0);
        assert!(
            !w.trace.contains(&Phase::WaitForAttention),
            "{wait} {attention}"
        );
    }
}

#[test]
fn dropping_the_request_while_waiting_releases_the_gate() {
    let mut w = World::new(cfg());
    w.wait_for_attention = true;
    w.task.start();
    w.run_until(Phase::WaitForAttention, 10.0);
    w.run_for(1.0);
    w.wait_for_attention = false;
    w.tick();
    assert_eq!(w.task.phase(), Phase::Approach);
}

#[test]
fn start_delay_holds_the_part_after_gripping() {
    let mut w = World::new(cfg());
    w.start_delay_s = 1.5;
    w.task.start();
    w.run_until(Phase::Approach, 10.0);
    let gripped = w.event_time(TaskEventKind::PartGripped);
    let approach = w.event_time(TaskEventKind::PhaseChanged {
        from: Phase::Fetch,
        to: Phase::Approach,
    });
    assert!(
        (approach - gripped - 1.5).abs() < 2.0 * DT,
        "{gripped} {approach}"
    );
}

#[test]
fn c_and_g_truth_table_per_phase() {
    // Walk the happy path and record (C, G) in every phase.
    let mut w = World::new(cfg());
    let mut seen = std::collections::HashMap::new();
    let mut record = |w: &World| {
        let entry = seen
            .entry(w.task.phase())
            .or_insert((w.task.collaborating(), w.task.incomplete()));
        assert_eq!(
            *entry,
            (w.task.collaborating(), w.task.incomplete()),
            "(C, G) constant within {}",
            w.task.phase()
        );
    };
    record(&w);
    w.wait_for_attention = true;
    w.task.start();
    while w.task.phase() != Phase::Present {
        w.tick();
        record(&w);
        if w.task.phase() == Phase::WaitForAttention && w.now > 4.0 {
            w.attention = true;
        }
    }
    w.hands = [Some(HANDOVER_TCP), None];
    while w.task.phase() != Phase::Done {
        w.tick();
        record(&w);
    }
    w.run_for(0.1);
    record(&w);
    let expected = [
        (Phase::Idle, false, true),
        (Phase::Fetch, false, true),
        (Phase::WaitForAttention, false, true),
        (Phase::Approach, true, true),
        (Phase::Present, true, true),
        (Phase::Release, true, true),
        (Phase::Retreat, false, false),
        (Phase::Done, false, false),
    ];
    for (phase, c, g) in expected {
        assert_eq!(seen.get(&phase), Some(&(c, g)), "{phase}");
        assert_eq!(phase.is_collaborating(), c);
    }
    assert_eq!(seen.len(), Phase::ALL.len());
}

#[test]
fn grasp_needs_the_full_t_grasp() {
    let c = cfg();
    let mut w = World::new(c);
    w.task.start();
    w.run_until(Phase::Present, 10.0);
    let near = Some([HANDOVER_TCP[0], HANDOVER_TCP[1] + 0.05, HANDOVER_TCP[2]]);
    let far = Some([HANDOVER_TCP[0], HANDOVER_TCP[1] + 0.5, HANDOVER_TCP[2]]);
    // Passing by: near for just under t_grasp, several times, with breaks.
    for _ in 0..5 {
        w.hands = [near, None];
        w.run_for(c.grasp_time_s - 0.05);
        w.hands = [far, None];
        w.run_for(0.1);
    }
    // Alternating hands never add up either.
    for _ in 0..3 {
        w.hands = [near, far];
        w.run_for(c.grasp_time_s * 0.6);
        w.hands = [far, near];
        w.run_for(c.grasp_time_s * 0.6);
    }
    // A tracking drop-out (None) breaks the run too.
    w.hands = [near, None];
    w.run_for(c.grasp_time_s * 0.6);
    w.hands = [None, None];
    w.tick();
    w.hands = [near, None];
    w.run_for(c.grasp_time_s * 0.6);
    assert_eq!(w.task.phase(), Phase::Present, "{:?}", w.kinds());
    // Just outside r_grasp never counts.
    w.hands = [
        Some([
            HANDOVER_TCP[0] + c.grasp_radius_m + 0.005,
            HANDOVER_TCP[1],
            HANDOVER_TCP[2],
        ]),
        None,
    ];
    w.run_for(c.grasp_time_s * 3.0);
    assert_eq!(w.task.phase(), Phase::Present);
    // Now it stays: grasp after t_grasp.
    w.hands = [near, None];
    let t0 = w.now;
    w.run_until(Phase::Release, 1.0);
    let t = w.event_time(TaskEventKind::GraspDetected { hand: 0 });
    assert!(t - t0 >= c.grasp_time_s - 1e-9 && t - t0 < c.grasp_time_s + 2.0 * DT);
}

#[test]
fn a_hand_at_the_tcp_before_present_does_not_count_early() {
    // The hand already waits at the handover point during the approach: t_grasp counts from
    // the start of Present.
    let c = cfg();
    let mut w = World::new(c);
    w.hands = [Some(HANDOVER_TCP), None];
    w.task.start();
    w.run_until(Phase::Present, 10.0);
    let present = w.now - DT;
    w.run_until(Phase::Release, 1.0);
    let t = w.event_time(TaskEventKind::GraspDetected { hand: 0 });
    assert!(t - present >= c.grasp_time_s - 1e-9);
}

#[test]
fn reset_after_done_allows_another_handover() {
    let mut w = World::new(cfg());
    w.task.start();
    w.hands = [Some(HANDOVER_TCP), None];
    w.run_until(Phase::Done, 20.0);
    w.task.reset();
    assert_eq!(w.task.phase(), Phase::Idle);
    assert!(w.task.incomplete());
    w.task.start();
    w.run_until(Phase::Done, 20.0);
}

#[test]
fn start_is_ignored_outside_idle_and_non_finite_time_is_ignored() {
    let mut task = HandoverTask::new(cfg());
    let mut ev = EventBuffer::<4>::new();
    task.step(&TaskInput::at(f64::NAN), &mut ev);
    task.start();
    task.step(&TaskInput::at(f64::NAN), &mut ev);
    assert_eq!(task.phase(), Phase::Idle);
    task.step(&TaskInput::at(1.0), &mut ev);
    assert_eq!(task.phase(), Phase::Fetch);
    task.start();
    assert_eq!(task.phase(), Phase::Fetch);
}

#[test]
fn event_buffer_is_fixed_capacity() {
    let mut task = HandoverTask::new(cfg());
    let mut ev = EventBuffer::<1>::new();
    assert_eq!(ev.capacity(), 1);
    task.start();
    let mut input = TaskInput::at(0.0);
    input.motion_finished = true;
    for i in 0..2000 {
        input.now_s = i as f64 * DT;
        task.step(&input, &mut ev);
    }
    assert_eq!(ev.len(), 1);
    assert!(ev.dropped() > 0);
    ev.clear();
    assert!(ev.is_empty());
}

fn raw(home: RawPose) -> RawTaskConfig {
    let c = cfg();
    let joints = |q| RawPose {
        joints_rad: Some(q),
        position_m: None,
        rotation_vector_rad: None,
    };
    RawTaskConfig {
        grasp_radius_m: c.grasp_radius_m,
        grasp_time_s: c.grasp_time_s,
        present_timeout_s: c.present_timeout_s,
        grip_dwell_s: c.grip_dwell_s,
        release_dwell_s: c.release_dwell_s,
        poses: RawPoses {
            home,
            pick: joints(c.pick_q_rad),
            handover: joints(c.handover_q_rad),
        },
    }
}

#[test]
fn config_validation() {
    let no_ik = |_: &[f64; 6], _: &[f64; 6]| -> Option<[f64; 6]> { None };
    let joints = RawPose {
        joints_rad: Some(cfg().home_q_rad),
        position_m: None,
        rotation_vector_rad: None,
    };
    assert_eq!(
        TaskConfig::from_raw_with(&raw(joints.clone()), no_ik).unwrap(),
        cfg()
    );

    let cartesian = RawPose {
        joints_rad: None,
        position_m: Some([0.4, 0.1, 0.5]),
        rotation_vector_rad: Some([0.0, 3.0, 0.0]),
    };
    // The IK is called with the pose and the elbow-up reference as the seed.
    let mut called = None;
    let got =
        TaskConfig::from_raw_with(&raw(cartesian.clone()), |p: &[f64; 6], seed: &[f64; 6]| {
            called = Some((*p, *seed));
            Some([0.1; 6])
        })
        .unwrap();
    assert_eq!(got.home_q_rad, [0.1; 6]);
    assert_eq!(
        called,
        Some((
            [0.4, 0.1, 0.5, 0.0, 3.0, 0.0],
            adapt::task::IK_REFERENCE_Q_RAD
        ))
    );
    assert!(matches!(
        TaskConfig::from_raw_with(&raw(cartesian.clone()), no_ik),
        Err(AdaptError::UnreachablePose { pose: "poses.home" })
    ));

    let both = RawPose {
        joints_rad: Some([0.0; 6]),
        ..cartesian.clone()
    };
    let half = RawPose {
        rotation_vector_rad: None,
        ..cartesian
    };
    let out_of_range = RawPose {
        joints_rad: Some([7.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        position_m: None,
        rotation_vector_rad: None,
    };
    for bad in [both, half, out_of_range] {
        let err = TaskConfig::from_raw_with(&raw(bad), no_ik).unwrap_err();
        assert!(err.to_string().contains("poses.home"), "{err}");
    }

    let mut r = raw(joints.clone());
    r.grasp_radius_m = 0.0;
    assert!(TaskConfig::from_raw_with(&r, no_ik).is_err());
    let mut r = raw(joints.clone());
    r.present_timeout_s = r.grasp_time_s;
    let err = TaskConfig::from_raw_with(&r, no_ik).unwrap_err();
    assert!(
        err.to_string()
            .starts_with("invalid value for `present_timeout_s`"),
        "{err}"
    );
    let mut r = raw(joints);
    r.release_dwell_s = f64::NAN;
    assert!(TaskConfig::from_raw_with(&r, no_ik).is_err());
}

#[test]
fn task_times_are_bounded_at_600_s_and_the_error_names_the_key() {
    let no_ik = |_: &[f64; 6], _: &[f64; 6]| -> Option<[f64; 6]> { None };
    let home = RawPose {
        joints_rad: Some(cfg().home_q_rad),
        position_m: None,
        rotation_vector_rad: None,
    };
    type Field = fn(&mut RawTaskConfig) -> &mut f64;
    let fields: [(&str, Field); 4] = [
        ("grasp_time_s", |r| &mut r.grasp_time_s),
        ("present_timeout_s", |r| &mut r.present_timeout_s),
        ("grip_dwell_s", |r| &mut r.grip_dwell_s),
        ("release_dwell_s", |r| &mut r.release_dwell_s),
    ];
    for (key, field) in fields {
        // 1e20 s passed validation at a077dd5 (issue 10).
        for bad in [600.5, 1e20] {
            let mut r = raw(home.clone());
            *field(&mut r) = bad;
            if key == "grasp_time_s" {
                r.present_timeout_s = 599.0; // keep present_timeout_s > grasp_time_s aside
            }
            let err = TaskConfig::from_raw_with(&r, no_ik)
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(&format!("`{key}`")) && err.contains("600"),
                "{err}"
            );
        }
    }
    let mut r = raw(home);
    r.present_timeout_s = 600.0;
    assert!(TaskConfig::from_raw_with(&r, no_ik).is_ok());
}
