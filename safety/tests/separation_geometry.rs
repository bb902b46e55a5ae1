//! SAF-REQ-007 by geometry: a hand or torso at the surface of any arm capsule (every link, the
//! gripper, the carried part), closer than S_p, stops the robot, at rest (kinematic mock) and
//! in motion (`SimRobot`, 2 ms mock clock); just beyond S_p it passes. And the figures the
//! README quotes for the margin the old three-point model had (run with `--nocapture`).

mod common;

use std::cell::RefCell;
use std::f64::consts::PI;
use std::rc::Rc;

use common::{BaseRamp, DT, MockRobot, Q_WORK, SharedSim, capsules, norm3, servo, tcp_speed};
use nalgebra::{Isometry3, Vector6};
use robot_io::geometry::{
    ARM_CAPSULES, Capsule, Point3, RawBodyModel, capsule_distance, closest_approaches,
    point_segment_distance,
};
use robot_io::kinematics::{flange_pose, jacobian, pose_from_vector};
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::{JointCommand, Joints, RobotState};
use safety::points::arm_points;
use safety::separation::{RobotMotion, protective_distance_m};
use safety::{
    ArmLink, BodyModel, BodyPart, HumanBody, Supervisor, SupervisorConfig, Torso, Verdict,
    Violation, WorldView,
};

/// How far outside a link's surface the body part is put [m].
const CLEARANCE_M: f64 = 0.001;

fn add(a: &Point3, b: &Point3) -> Point3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn scaled(a: &Point3, k: f64) -> Point3 {
    [a[0] * k, a[1] * k, a[2] * k]
}

fn cross(a: &Point3, b: &Point3) -> Point3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn unit(a: &Point3) -> Point3 {
    scaled(a, 1.0 / norm3(a))
}

fn lerp(a: &Point3, b: &Point3, t: f64) -> Point3 {
    std::array::from_fn(|k| a[k] + (b[k] - a[k]) * t)
}

/// Two unit vectors perpendicular to `axis` and to each other.
fn perpendiculars(axis: &Point3) -> (Point3, Point3) {
    let a = unit(axis);
    let helper = if a[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let u = unit(&cross(&a, &helper));
    (u, cross(&a, &u))
}

/// The surface distance from a point to every capsule but `skip` [m].
fn others_distance(caps: &[Capsule; ARM_CAPSULES], skip: usize, p: &Point3) -> f64 {
    caps.iter()
        .enumerate()
        .filter(|(j, _)| *j != skip)
        .map(|(_, c)| capsule_distance(c, &Capsule::point(*p, 0.0)))
        .fold(f64::INFINITY, f64::min)
}

/// The surface distance from a point to the arm [m].
fn arm_distance(caps: &[Capsule; ARM_CAPSULES], p: &Point3) -> f64 {
    others_distance(caps, usize::MAX, p)
}

/// A point `offset_m` outside capsule `k`'s surface, and its outward direction, where every
/// other capsule is at least 1 cm further: the segment's middle if such a direction exists
/// there, else a point nearer an end, else on an end cap. The search is over 72 directions
/// around the segment (and 36 × 6 on each cap).
fn exposed_surface_point(
    caps: &[Capsule; ARM_CAPSULES],
    k: usize,
    offset_m: f64,
) -> (Point3, Point3) {
    let c = caps[k];
    let axis: Point3 = std::array::from_fn(|i| c.b_m[i] - c.a_m[i]);
    let (u, v) = perpendiculars(&axis);
    let out = c.radius_m + offset_m;
    // (1 nm of tolerance: at the part's far pole the gap is exactly 1 cm by construction —
    // part 0.03 m + radius 0.04 m beyond the fingertips, the gripper's cap 0.06 m.)
    let wanted = offset_m + 0.01 - 1e-9;
    let best_of = |candidates: &mut dyn Iterator<Item = (Point3, Point3)>| {
        candidates
            .map(|(p, n)| (others_distance(caps, k, &p), p, n))
            .fold((f64::NEG_INFINITY, [0.0; 3], [0.0; 3]), |b, x| {
                if x.0 > b.0 { x } else { b }
            })
    };
    let ring = |centre: Point3, along: Option<(Point3, f64)>, phi: f64| {
        let radial = add(&scaled(&u, phi.cos()), &scaled(&v, phi.sin()));
        let n = match along {
            None => radial,
            Some((dir, theta)) => add(&scaled(&radial, theta.cos()), &scaled(&dir, theta.sin())),
        };
        (add(&centre, &scaled(&n, out)), n)
    };
    for t in [0.5, 0.4, 0.6, 0.3, 0.7, 0.2, 0.8, 0.1, 0.9] {
        let centre = lerp(&c.a_m, &c.b_m, t);
        let mut it = (0..72).map(|j| ring(centre, None, j as f64 * PI / 36.0));
        let (gap, p, n) = best_of(&mut it);
        if gap >= wanted {
            return (p, n);
        }
    }
    let ax = unit(&axis);
    let mut caps_points = [(c.a_m, scaled(&ax, -1.0)), (c.b_m, ax)]
        .into_iter()
        .flat_map(|(end, dir)| {
            (1..=6).flat_map(move |e| {
                (0..36).map(move |j| {
                    ring(end, Some((dir, e as f64 * PI / 12.0)), j as f64 * PI / 18.0)
                })
            })
        });
    let (gap, p, n) = best_of(&mut caps_points);
    assert!(gap >= wanted, "no exposed surface on capsule {k} ({gap})");
    (p, n)
}

/// The first point along `p + s·n` (0.5 mm steps) whose surface distance to the arm, at every
/// configuration in `configs`, is at least `required_m`; and the step before it (closer than
/// `required_m` at some configuration).
fn just_beyond(
    configs: &[[Capsule; ARM_CAPSULES]],
    p: &Point3,
    n: &Point3,
    required_m: f64,
) -> (Point3, Point3) {
    let at = |s: f64| add(p, &scaled(n, s));
    let distance = |q: &Point3| {
        configs
            .iter()
            .map(|c| arm_distance(c, q))
            .fold(f64::INFINITY, f64::min)
    };
    for i in 1..8000 {
        let s = i as f64 * 0.0005;
        if distance(&at(s)) >= required_m {
            return (at(s), at(s - 0.0005));
        }
    }
    panic!("never beyond {required_m} m");
}

fn hand_at(p: Point3) -> HumanBody {
    HumanBody {
        right_hand_m: Some(p),
        ..HumanBody::NONE
    }
}

/// A torso whose shoulder midpoint is `p`, facing along `facing`.
fn torso_at(p: Point3, facing: Point3) -> HumanBody {
    HumanBody {
        torso: Some(Torso {
            shoulder_mid_m: p,
            normal: facing,
        }),
        ..HumanBody::NONE
    }
}

/// The configuration with the torso shrunk to a 1 mm sphere about the shoulder midpoint (a
/// "torso point"), so that it can touch one capsule alone; the default torso is 0.44 m wide
/// and reaches several links at once (`saf_req_007_default_torso_and_head_radii_count` checks
/// its size).
fn torso_point_config() -> SupervisorConfig {
    let mut config = SupervisorConfig::ur5e();
    config.body = BodyModel::new(RawBodyModel {
        head_radius_m: 0.12,
        torso_radius_m: 0.001,
        torso_length_m: 0.0,
    })
    .unwrap();
    config
}

/// Which body part a test case places, and how.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Probe {
    Hand,
    TorsoPoint,
}

impl Probe {
    fn part(self) -> BodyPart {
        match self {
            Probe::Hand => BodyPart::RightHand,
            Probe::TorsoPoint => BodyPart::Torso,
        }
    }

    fn config(self) -> SupervisorConfig {
        match self {
            Probe::Hand => SupervisorConfig::ur5e(),
            Probe::TorsoPoint => torso_point_config(),
        }
    }

    /// The offset of the tracked point from the link's surface for a part surface 1 mm away.
    fn offset_m(self) -> f64 {
        match self {
            Probe::Hand => CLEARANCE_M,
            Probe::TorsoPoint => CLEARANCE_M + 0.001,
        }
    }

    fn body(self, p: Point3, outward: Point3) -> HumanBody {
        match self {
            Probe::Hand => hand_at(p),
            // Facing the robot.
            Probe::TorsoPoint => torso_at(p, scaled(&outward, -1.0)),
        }
    }
}

/// The verdict is a SAF-REQ-007 stop naming `part` and `link` at `distance` [m]; returns S_p.
fn assert_separation_stop(
    v: Verdict,
    part: BodyPart,
    link: ArmLink,
    distance: f64,
    what: &str,
) -> f64 {
    match v {
        Verdict::Stopped {
            violation:
                Violation::Separation {
                    part: p,
                    link: l,
                    distance_m,
                    required_m,
                },
        } => {
            assert_eq!((p, l), (part, link), "{what}");
            assert!((distance_m - distance).abs() < 1e-9, "{what}: {distance_m}");
            assert!(distance_m < required_m, "{what}");
            required_m
        }
        other => panic!("{what}: {other:?}"),
    }
}

// --- at rest (kinematic mock) ---

fn at_rest(probe: Probe) {
    let config = probe.config();
    let part = probe.part();
    let caps = capsules(&config.arm, &Q_WORK);
    let s_rest = protective_distance_m(&config.separation, part, RobotMotion::REST, 0.0);
    for link in ArmLink::ALL {
        let what = format!("{probe:?} at the {link}, at rest");
        let (p, n) = exposed_surface_point(&caps, link.index(), probe.offset_m());
        let step = |body: HumanBody| {
            let (robot, _) = MockRobot::at(Q_WORK);
            let mut sup = Supervisor::new(robot, config).unwrap();
            let mut state = RobotState::default();
            sup.read_state(&mut state).unwrap();
            let world = WorldView {
                human: body,
                ..WorldView::clear(0.0)
            };
            sup.step(&servo(Q_WORK), &world)
        };
        // 1 mm from the surface: stop, naming the part and the link.
        let v = step(probe.body(p, n));
        let required = assert_separation_stop(v, part, link, CLEARANCE_M, &what);
        assert!((required - s_rest).abs() < 1e-12, "{what}");
        // Just beyond S_p (from every capsule) it passes; just inside it stops.
        let target = s_rest + probe.offset_m() - CLEARANCE_M;
        let (out, _) = just_beyond(&[caps], &p, &n, target + 0.0005);
        assert_eq!(
            step(probe.body(out, n)),
            Verdict::Passed,
            "{what}, beyond S_p"
        );
        let (_, inner) = just_beyond(&[caps], &p, &n, target - 0.0005);
        let v = step(probe.body(inner, n));
        assert!(
            matches!(
                v,
                Verdict::Stopped {
                    violation: Violation::Separation { .. }
                }
            ),
            "{what}, 1 mm inside S_p: {v:?}"
        );
    }
}

#[test]
fn saf_req_007_hand_at_each_link_surface_stops_at_rest() {
    at_rest(Probe::Hand);
}

#[test]
fn saf_req_007_torso_at_each_link_surface_stops_at_rest() {
    at_rest(Probe::TorsoPoint);
}

// --- in motion (SimRobot) ---

/// A `SimRobot` at `Q_WORK` behind a supervisor, its base turning so the TCP moves at about
/// 0.2 m/s (collaborating: the cap is 0.25 m/s).
struct Moving {
    sim: Rc<RefCell<SimRobot>>,
    sup: Supervisor<SharedSim>,
    state: RobotState,
    plan: BaseRamp,
}

impl Moving {
    fn new(config: SupervisorConfig) -> Moving {
        let mut sim_config = SimConfig::ur5e();
        sim_config.initial_q_rad = Q_WORK;
        let sim = Rc::new(RefCell::new(SimRobot::new(sim_config).unwrap()));
        let sup = Supervisor::new(SharedSim(sim.clone()), config).unwrap();
        let base = 0.2 / tcp_speed(&Q_WORK, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let mut m = Moving {
            sim,
            sup,
            state: RobotState::default(),
            plan: BaseRamp::new(Q_WORK, base, 2.0),
        };
        m.sup.read_state(&mut m.state).unwrap();
        for _ in 0..400 {
            let cmd = m.plan.next();
            assert_eq!(m.cycle(&cmd, HumanBody::NONE), Verdict::Passed);
        }
        assert!(norm3(&m.state.actual_tcp_speed) > 0.15);
        m
    }

    fn cycle(&mut self, cmd: &JointCommand, human: HumanBody) -> Verdict {
        let world = WorldView {
            human,
            collaborating: true,
            ..WorldView::clear(self.state.timestamp_s)
        };
        let v = self.sup.step(cmd, &world);
        self.sim.borrow_mut().step();
        self.sup.read_state(&mut self.state).unwrap();
        v
    }

    /// S_p and the stopping configuration the supervisor will use for `cmd`, computed here
    /// independently: v_r the larger of the commanded and measured TCP speed, T_s from the
    /// faster of the commanded and measured joint speeds at π rad/s².
    fn expected(&self, cmd: &JointCommand, part: BodyPart) -> (f64, Joints) {
        let JointCommand::Servo { q, .. } = *cmd else {
            panic!()
        };
        let Some(JointCommand::Servo { q: from, .. }) = self.sup.last_sent().map(|c| *c.command())
        else {
            panic!()
        };
        let v: Joints = std::array::from_fn(|j| (q[j] - from[j]) / DT);
        let fastest = |x: &Joints| x.iter().fold(0.0_f64, |m, a| m.max(a.abs()));
        let t_stop = fastest(&v).max(fastest(&self.state.actual_qd)) / PI;
        let speed = tcp_speed(&from, &v).max(norm3(&self.state.actual_tcp_speed));
        let motion = RobotMotion {
            speed_m_s: speed,
            stopping_time_s: t_stop,
        };
        let s_p = protective_distance_m(&self.sup.config().separation, part, motion, 0.0);
        let q_stop = std::array::from_fn(|j| q[j] + v[j] * t_stop / 2.0);
        (s_p, q_stop)
    }
}

fn in_motion(probe: Probe) {
    let config = probe.config();
    let part = probe.part();
    for link in ArmLink::ALL {
        let what = format!("{probe:?} at the {link}, in motion");
        // 1 mm from the surface at the measured joints: stop, naming the part and the link.
        let mut m = Moving::new(config);
        let caps = capsules(&config.arm, &m.state.actual_q);
        let (p, n) = exposed_surface_point(&caps, link.index(), probe.offset_m());
        let cmd = m.plan.next();
        let (s_p, _) = m.expected(&cmd, part);
        let v = m.cycle(&cmd, probe.body(p, n));
        let required = assert_separation_stop(v, part, link, CLEARANCE_M, &what);
        assert!(
            (required - s_p).abs() < 0.01 * s_p,
            "{what}: {required} vs {s_p}"
        );
        assert!(
            required > 0.4,
            "{what}: S_p {required} should include the motion"
        );
        // The stop reaches the robot: it decelerates to rest.
        let stop = *m.sup.last_sent().unwrap().command();
        assert!(matches!(stop, JointCommand::Stop { .. }), "{what}");
        // Just beyond S_p, now and at the stopping configuration: the motion goes on.
        let mut m = Moving::new(config);
        let caps = capsules(&config.arm, &m.state.actual_q);
        let cmd = m.plan.next();
        let (s_p, q_stop) = m.expected(&cmd, part);
        let stop_caps = capsules(&config.arm, &q_stop);
        let target = 1.01 * s_p + probe.offset_m() - CLEARANCE_M;
        let (out, _) = just_beyond(&[caps, stop_caps], &p, &n, target);
        assert_eq!(
            m.cycle(&cmd, probe.body(out, n)),
            Verdict::Passed,
            "{what}, beyond S_p = {s_p}"
        );
    }
}

#[test]
fn saf_req_007_hand_at_each_link_surface_stops_in_motion() {
    in_motion(Probe::Hand);
}

#[test]
fn saf_req_007_torso_at_each_link_surface_stops_in_motion() {
    in_motion(Probe::TorsoPoint);
}

/// The default body's sizes count: the head is a 0.12 m sphere, the torso a 0.22 m capsule
/// 0.5 m down the spine. At `Q_WORK` the tool points down.
#[test]
fn saf_req_007_default_torso_and_head_radii_count() {
    let config = SupervisorConfig::ur5e();
    let caps = capsules(&config.arm, &Q_WORK);
    let step = |body: HumanBody| {
        let (robot, _) = MockRobot::at(Q_WORK);
        let mut sup = Supervisor::new(robot, config).unwrap();
        let mut state = RobotState::default();
        sup.read_state(&mut state).unwrap();
        let world = WorldView {
            human: body,
            ..WorldView::clear(0.0)
        };
        sup.step(&servo(Q_WORK), &world)
    };
    // By hand: S_p at rest for the head and the torso (walking, 1.6 m/s):
    // 1.6·0.1 + 0.1 + 0.05 + 0.02 = 0.33 m.
    let s_rest = protective_distance_m(&config.separation, BodyPart::Head, RobotMotion::REST, 0.0);
    assert!((s_rest - 0.33).abs() < 1e-12);
    let part = caps[ArmLink::Part.index()];
    let down = unit(&std::array::from_fn(|k| part.b_m[k] - part.a_m[k]));
    assert!(down[2] < -0.99, "the tool points down: {down:?}");

    // The head keypoint 0.12 + 0.001 m below the part's end: its surface is 1 mm away.
    let head = |d: f64| HumanBody {
        head_m: Some(common::beyond_part(&config.arm, &Q_WORK, 0.12 + d)),
        ..HumanBody::NONE
    };
    let v = step(head(CLEARANCE_M));
    assert_separation_stop(v, BodyPart::Head, ArmLink::Part, CLEARANCE_M, "head");
    assert_eq!(step(head(s_rest + 0.001)), Verdict::Passed);
    assert!(step(head(s_rest - 0.001)).is_stop());

    // The torso beside the gripper, facing it: the shoulder midpoint level with the gripper's
    // middle, the spine straight down, parallel to the tool axis. Its surface is 1 mm from the
    // gripper's when the shoulder midpoint is 0.06 + 0.22 + 0.001 m from the gripper's axis.
    // Of 36 horizontal directions, the one where the torso keeps furthest from the other links.
    let g = caps[ArmLink::Gripper.index()];
    let mid = lerp(&g.a_m, &g.b_m, 0.5);
    let torso_from = |side: Point3| {
        move |d: f64| {
            torso_at(
                add(&mid, &scaled(&side, 0.06 + 0.22 + d)),
                scaled(&side, -1.0),
            )
        }
    };
    let others = |body: &HumanBody| {
        let t = config.body.capsule(body, BodyPart::Torso).unwrap();
        caps.iter()
            .enumerate()
            .filter(|(j, _)| *j != ArmLink::Gripper.index())
            .map(|(_, c)| capsule_distance(c, &t))
            .fold(f64::INFINITY, f64::min)
    };
    let side = (0..36)
        .map(|j| {
            let phi = j as f64 * PI / 18.0;
            [phi.cos(), phi.sin(), 0.0]
        })
        .max_by(|a, b| {
            others(&torso_from(*a)(CLEARANCE_M)).total_cmp(&others(&torso_from(*b)(CLEARANCE_M)))
        })
        .unwrap();
    let torso = torso_from(side);
    let body = torso(CLEARANCE_M);
    assert!(
        others(&body) > 0.005,
        "the torso touches another link: {}",
        others(&body)
    );
    let near = closest_approaches(&caps, &body, &config.body)[BodyPart::Torso.index()].unwrap();
    assert_eq!(near.link, ArmLink::Gripper, "{near:?}");
    // The tool axis is 0.8 mrad off vertical at Q_WORK, so not exactly 1 mm.
    assert!((near.distance_m - CLEARANCE_M).abs() < 1e-4, "{near:?}");
    let v = step(body);
    assert_separation_stop(
        v,
        BodyPart::Torso,
        ArmLink::Gripper,
        near.distance_m,
        "torso",
    );
    // Out beyond S_p from every capsule it passes.
    let far = (1..1000)
        .map(|i| torso(i as f64 * 0.001))
        .find(|b| {
            closest_approaches(&caps, b, &config.body)[BodyPart::Torso.index()]
                .unwrap()
                .distance_m
                >= s_rest + 0.0005
        })
        .unwrap();
    assert_eq!(step(far), Verdict::Passed);
}

// --- the margin the three-point model had (README) ---

/// Joints for a flange pose `[x, y, z, rx, ry, rz]` (RTDE form) by damped least squares from
/// `q0`, converging on the branch nearest `q0` (as `config/handover.toml` asks of its IK).
fn ik(pose: &[f64; 6], q0: &Joints) -> Joints {
    let target = pose_from_vector(pose);
    let mut q = *q0;
    for _ in 0..5000 {
        let t = flange_pose(&q);
        let dp = target.translation.vector - t.translation.vector;
        let dr = (target.rotation * t.rotation.inverse()).scaled_axis();
        let e = Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z);
        if e.norm() < 1e-12 {
            return q;
        }
        let j = jacobian(&q, &Isometry3::identity());
        let damped = j * j.transpose() + nalgebra::Matrix6::identity() * 1e-4;
        let dq = j.transpose() * damped.try_inverse().unwrap() * e;
        // Small steps follow the solution branch continuously from q0.
        let k = (0.02 / dq.amax()).min(1.0);
        for (a, b) in q.iter_mut().zip(dq.iter()) {
            *a += b * k;
        }
    }
    panic!("IK did not converge for {pose:?}");
}

fn toml_array(v: &toml::Value, path: &[&str]) -> [f64; 6] {
    let mut x = v;
    for key in path {
        x = &x[*key];
    }
    let a = x.as_array().unwrap();
    std::array::from_fn(|k| a[k].as_float().unwrap())
}

/// For a hand at the surface of every capsule (links, gripper, part), at the poses of
/// `config/handover.toml` (home, pick by IK, handover) and along joint-space motions between
/// them: the true surface distance is 0; the old model estimated its separation as the
/// distance to the nearest of the three DH points (TCP flange, wrist 1, elbow) minus
/// Z_r = 0.06 m, and stopped the robot at rest only below v_h·T_r + C + Z_d = 0.35 m. The
/// test prints the worst over-estimate per link (README, "Separation monitoring") and asserts
/// the figures.
#[test]
fn saf_req_007_three_point_model_margin() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../config/handover.toml");
    let file: toml::Value = toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let poses = ["controller", "task", "poses"];
    let home = toml_array(&file, &[poses[0], poses[1], poses[2], "home", "joints_rad"]);
    let handover = toml_array(
        &file,
        &[poses[0], poses[1], poses[2], "handover", "joints_rad"],
    );
    let pick_pose: [f64; 6] = {
        let p = &file[poses[0]][poses[1]][poses[2]]["pick"];
        let pos = p["position_m"].as_array().unwrap();
        let rot = p["rotation_vector_rad"].as_array().unwrap();
        std::array::from_fn(|k| {
            if k < 3 {
                pos[k].as_float().unwrap()
            } else {
                rot[k - 3].as_float().unwrap()
            }
        })
    };
    let pick = ik(&pick_pose, &home);
    let motions = [(home, pick), (pick, handover), (handover, home)];
    let old_z_r = 0.06;
    let old_rest_threshold = 2.0 * 0.1 + 0.1 + 0.05; // v_h T_r + C + Z_d, Z_r counted above
    let arm = SupervisorConfig::ur5e().arm;

    // Worst over-estimate per link: (over-estimate [m], q, point).
    let mut worst = [(f64::NEG_INFINITY, [0.0; 6], [0.0; 3]); ARM_CAPSULES];
    let mut unstopped = [0usize; ARM_CAPSULES];
    let mut samples = [0usize; ARM_CAPSULES];
    for (from, to) in motions {
        for i in 0..=20 {
            let q: Joints = std::array::from_fn(|j| from[j] + (to[j] - from[j]) * i as f64 / 20.0);
            let caps = capsules(&arm, &q);
            let old = arm_points(&q);
            let dh = [old.tcp, old.wrist, old.elbow];
            for (k, c) in caps.iter().enumerate() {
                let axis: Point3 = std::array::from_fn(|m| c.b_m[m] - c.a_m[m]);
                let (u, v) = perpendiculars(&axis);
                let ax = unit(&axis);
                let mut points = Vec::new();
                for t in 0..=20 {
                    let centre = lerp(&c.a_m, &c.b_m, t as f64 / 20.0);
                    for j in 0..24 {
                        let phi = j as f64 * PI / 12.0;
                        let n = add(&scaled(&u, phi.cos()), &scaled(&v, phi.sin()));
                        points.push(add(&centre, &scaled(&n, c.radius_m)));
                    }
                }
                for (end, dir) in [(c.a_m, scaled(&ax, -1.0)), (c.b_m, ax)] {
                    for e in 1..=6 {
                        let theta = e as f64 * PI / 12.0;
                        for j in 0..24 {
                            let phi = j as f64 * PI / 12.0;
                            let radial = add(&scaled(&u, phi.cos()), &scaled(&v, phi.sin()));
                            let n = add(&scaled(&radial, theta.cos()), &scaled(&dir, theta.sin()));
                            points.push(add(&end, &scaled(&n, c.radius_m)));
                        }
                    }
                }
                for p in points {
                    // Only points on the outer surface (not inside another capsule).
                    let inside_other = caps.iter().enumerate().any(|(j, o)| {
                        j != k && point_segment_distance(&p, &o.a_m, &o.b_m) < o.radius_m - 1e-9
                    });
                    if inside_other {
                        continue;
                    }
                    let estimate = dh
                        .iter()
                        .map(|d| norm3(&std::array::from_fn::<f64, 3, _>(|m| p[m] - d[m])))
                        .fold(f64::INFINITY, f64::min)
                        - old_z_r;
                    samples[k] += 1;
                    if estimate >= old_rest_threshold {
                        unstopped[k] += 1;
                    }
                    if estimate > worst[k].0 {
                        worst[k] = (estimate, q, p);
                    }
                }
            }
        }
    }
    println!("pick joints (IK from home): {pick:.4?}");
    println!(
        "hand at the surface (true distance 0) vs the three-point estimate (nearest DH point − 0.06 m):"
    );
    for link in ArmLink::ALL {
        let (over, q, p) = worst[link.index()];
        println!(
            "  {:<10} over-estimate up to {over:.3} m (at {p:.3?}, q = {q:.3?}); \
             {}/{} surface samples beyond the old at-rest stop distance 0.35 m",
            link.name(),
            unstopped[link.index()],
            samples[link.index()]
        );
    }
    for link in [ArmLink::Shoulder, ArmLink::UpperArm] {
        let (i, n) = (unstopped[link.index()], samples[link.index()]);
        println!(
            "  {link}: {:.0} % of its surface out of the old at-rest reach",
            100.0 * i as f64 / n as f64
        );
    }
    let overall = worst.iter().map(|w| w.0).fold(f64::NEG_INFINITY, f64::max);
    println!("  worst over all links: {overall:.3} m");

    // A worked example, by hand, at q = 0: a hand touching the top of the forearm capsule at
    // its middle, (−0.6211, −0.007, 0.1625 + 0.053). The DH points: the elbow (−0.425, 0,
    // 0.1625) and the wrist (−0.8172, 0, 0.1625) are both √(0.1961² + 0.007² + 0.053²) =
    // 0.2033 m away; the old estimate 0.2033 − 0.06 = 0.143 m for a hand that touches.
    let q0 = arm_points(&[0.0; 6]);
    let touch = [-0.6211, -0.007, 0.1625 + 0.053];
    let to = |d: &Point3| norm3(&std::array::from_fn::<f64, 3, _>(|m| touch[m] - d[m]));
    assert!((to(&q0.elbow) - 0.2033).abs() < 5e-4 && (to(&q0.wrist) - 0.2033).abs() < 5e-4);
    assert!(arm_distance(&capsules(&arm, &[0.0; 6]), &touch) < 1e-9);

    // The figures the README quotes (±5 mm: the sampling is 1/20 of each motion).
    let expected = [
        (ArmLink::Shoulder, 0.468),
        (ArmLink::UpperArm, 0.358),
        (ArmLink::Elbow, 0.157),
        (ArmLink::Forearm, 0.145),
        (ArmLink::Wrist1, 0.078),
        (ArmLink::Wrist2, 0.126),
        (ArmLink::Wrist3, 0.115),
        (ArmLink::Gripper, 0.108),
        (ArmLink::Part, 0.130),
    ];
    for (link, figure) in expected {
        let w = worst[link.index()].0;
        assert!(
            (w - figure).abs() < 0.005,
            "{link}: {w:.3} m, README says {figure}"
        );
        // Only the shoulder and the upper arm near it were out of the old at-rest reach.
        let beyond = unstopped[link.index()] > 0;
        assert_eq!(
            beyond,
            matches!(link, ArmLink::Shoulder | ArmLink::UpperArm),
            "{link}"
        );
    }
    assert!((overall - 0.468).abs() < 0.005);
    // Most of the shoulder drum, and a few per cent of the upper arm (next to the shoulder),
    // were beyond the old at-rest stop distance: a hand touching them was not stopped.
    let share = |l: ArmLink| unstopped[l.index()] as f64 / samples[l.index()] as f64;
    assert!(
        share(ArmLink::Shoulder) > 0.75,
        "{}",
        share(ArmLink::Shoulder)
    );
    assert!(
        share(ArmLink::UpperArm) < 0.05,
        "{}",
        share(ArmLink::UpperArm)
    );
}
