//! The KTH handover dataset layout (OptiTrack rigid bodies at 120 Hz) → CueFrames for the taker.
//!
//! One handover folder (Khanna, Björkman, Smith, "A Multimodal Data Set of Human Handovers",
//! RO-MAN 2023; one is bundled in `data/human-motion/kth-handover/`) holds one CSV per rigid body,
//! `<person>_<segment>_pose_saved.csv` with the header `x,y,z,q0,q1,q2,q3`, plus
//! `Wrench_{giver,taker,interaction}_saved.csv` with `Fx,Fy,Fz,Tx,Ty,Tz`. Row k (0-based, after
//! the header) is at t = k / 120 s. A giver hands a baton to a taker; our operator plays the
//! **taker**, and the giver plays the robot.
//!
//! # Frame conventions, worked out from the bundled recording
//!
//! The dataset does not document the quaternion order. `scripts/analysis/kth_frames.py`
//! (standard library only) derives every convention below from the data; the numbers quoted are
//! its output on the bundled recording.
//!
//! - **Up is +z; positions are metres.** Median heights: taker head 1.483 m, chest 1.145 m,
//!   hip 0.904 m; giver head 1.441 m, chest 1.120 m. This is the workspace frame of the spec as
//!   is: no axis permutation is applied. The taker stands at x ≈ +0.62, the giver at
//!   x ≈ −0.55, and the handover happens between them at x ≈ 0.
//! - **The scalar w is `q3`: the order is `x,y,z,w`, and q maps body → world**
//!   (p_world = R(q) p_body + x). Evidence from segment rigidity: each skeleton segment's origin
//!   sits at its proximal joint, so a child's origin expressed in its parent's frame,
//!   R_parentᵀ (x_child − x_parent), must be constant. Summing the per-axis standard deviations of
//!   that offset over 24 parent→child pairs (hip→ab→chest→neck→head, chest→shoulder→upper arm→
//!   forearm→hand, both sides, both people) over all 801 rows:
//!   - w = q3, body → world: **35.8 mm** (most pairs 0.0 mm; the largest are the wrists,
//!     10.9 and 14.1 mm, and ab→chest, 2.7 and 3.5 mm);
//!   - w = q3, world → body: 1551.7 mm; w = q0, body → world: 1337.7 mm; w = q0, world → body:
//!     1042.6 mm.
//!
//!   With w = q3 the offsets are the skeleton's bone vectors: +z along the spine (hip→ab
//!   0.063–0.067 m, chest→neck 0.206–0.219 m), +x along the left arm and −x along the right
//!   (upper arm 0.240–0.252 m, forearm 0.227–0.274 m). Note that a facing test alone does *not*
//!   decide the order: with w = q0 the head's −y axis is 9.5° from world up and its +x axis 19.2°
//!   from the direction to the giver's head, a plausible-looking frame too. Rigidity decides it.
//! - **Body axes (w = q3): +z is up, +x is the person's left, so −y is forward (the facing
//!   axis) for both head and chest.** Median angles over all rows:
//!   - taker head: +z is 16.9° from world up (the head is pitched down); −y is 19.3° from the
//!     direction to the giver's head and 28.0° from the direction to the baton;
//!   - taker chest: +z is 4.1° from world up; −y, projected on the horizontal plane, is 5.6° from
//!     the horizontal direction to the giver's chest;
//!   - giver, as a check: chest +z 5.4° from up, −y 8.6° (horizontal) from the taker's chest.
//!
//!   Against the handover point (the baton where the taker's grip force first exceeds 5 N),
//!   the taker's head −y axis has a median deviation of 21.7° before the giver reaches,
//!   18.7° during the reach, 24.9° during the grasp and 25.9° after the release.
//! - **The taker receives with the right hand.** The right-hand rigid body's origin (at the
//!   wrist) comes to 0.21 m from the baton's origin at t ≈ 3.05 s and stays within 0.20–0.23 m
//!   to the end (last row 0.211 m); the left hand never comes closer than 0.621 m. 0.20–0.21 m is
//!   the holding distance: the giver's right hand sits at 0.203–0.207 m from the baton while it
//!   holds it at the start. With the taker facing −x, their right is +y: the right hand is at
//!   median y = +0.089, the left at −0.319.
//! - **The transfer** (rows at 120 Hz):
//!   - 0–0.8 s: the giver sets the baton down at z ≈ 0.81 m (giver |F| 19 N → 1 N);
//!   - 2.0 s: the giver grasps it again (|F| 15 N at row 240); the baton's speed over 0.1 s
//!     first exceeds 0.2 m/s at row 254 (2.117 s): the reach onset. While the giver set it down
//!     (rows 12–71) that speed stayed ≤ 0.097 m/s, while it lay on the table (rows 72–230)
//!     ≤ 0.022 m/s; during the reach and transfer it peaks at 0.69 m/s;
//!   - the baton rises to z ≈ 1.10 m by 2.95 s; the taker's right hand arrives there
//!     (its One-Euro-filtered speed stays below 0.10 m/s on rows 364–421, 3.033–3.508 s);
//!   - 3.300 s (row 396): the taker's |F| first exceeds 5 N (the grasp); the baton is at
//!     (0.001, −0.173, 1.098) m;
//!   - 3.558 s (row 427): the giver's |F| falls below 1 N (the release: the transfer is
//!     complete); the giver's hand then leaves (0.26 m from the baton at 3.75 s, 1.03 m at 4.5 s);
//!   - 3.6–5.8 s: the taker carries the baton to (0.26, 0.31, 0.82) m, to their front right, and
//!     sets it down (their |F| falls from ≈ 30 N to 1.6 N at 6.0 s).
//!
//! # Cues
//!
//! - Head cue: the head rigid body's origin, facing its −y axis, confidence 1.0.
//! - Body cue: the midpoint of the two upper-arm origins (the shoulder joints), or the chest's
//!   origin when an upper arm is missing; facing the chest's −y axis; confidence 1.0.
//! - Hand cues: `hands[Hand::Left as usize]` from `taker_LHand`, `hands[Hand::Right as usize]`
//!   from `taker_RHand` (the origin, at the wrist), confidence 1.0. Both are given; the assessor's
//!   active-hand rule picks one.
//! - A row with an empty or non-finite value, or a quaternion of norm outside [0.5, 2], is a
//!   missing rigid body: the cues that need it are `None`. A file shorter than the longest one
//!   leaves its later rows missing. The bundled recording has no such row.
//! - A row with the wrong number of fields, or a field that is not a number, is an error naming
//!   the file, line and column ([`AssessError::Csv`]). So is a wrong header.
//!
//! # Robot context: the giver plays the robot
//!
//! - **Reach onset**: the first row whose baton speed, |x_k − x_{k−w}| / (w / 120 Hz) with
//!   w = round(`speed_window_s` · 120), exceeds [`KthOptions::reach_speed_m_s`].
//! - **Grasp**: the first row where the taker's |F| exceeds [`KthOptions::grasp_force_n`].
//! - **Release** (the transfer is complete): the first row at or after the grasp where the
//!   giver's |F| falls below [`KthOptions::release_force_n`].
//! - **C(t) = 1 from the reach onset (inclusive) until the release (exclusive)**: the giver is
//!   approaching, presenting and then waiting for the taker to take the load, as the robot would.
//!   Without a detected onset C is never set; without a release it lasts to the end.
//!   [`KthOptions::collaboration_s`] replaces this with an explicit interval.
//! - **G(t) = 1 until the release (exclusive)**: until the taker holds the baton alone, the
//!   collaborative operation is incomplete. Without a release G holds throughout.
//!
//! On the bundled recording, with the defaults: onset 2.117 s, grasp 3.300 s, release 3.558 s,
//! so C holds for 1.44 s.

use std::path::{Path, PathBuf};

use crate::Vec3;
use crate::cue::{BodyCue, CueFrame, Hand, HandCue, HeadCue, RobotContext};
use crate::error::{AssessError, Result};

/// The recording rate of the dataset [Hz].
pub const KTH_RATE_HZ: f64 = 120.0;

/// The facing axis of the head and chest rigid bodies, in body coordinates [-]: −y (see the
/// module docs for the evidence).
pub const FACING_AXIS: Vec3 = Vec3::new(0.0, -1.0, 0.0);

const POSE_HEADER: [&str; 7] = ["x", "y", "z", "q0", "q1", "q2", "q3"];
const WRENCH_HEADER: [&str; 6] = ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"];

/// How a KTH handover folder becomes CueFrames, and how the robot context is derived.
#[derive(Debug, Clone, PartialEq)]
pub struct KthOptions {
    /// The recording rate; row k is at t = k / `rate_hz` [Hz]. Default 120.
    pub rate_hz: f64,
    /// The interval over which the baton speed is measured for the reach onset [s]. Default 0.1.
    pub speed_window_s: f64,
    /// Reach onset: the baton speed over `speed_window_s` exceeds this [m/s]. Default 0.2
    /// (the bundled recording: ≤ 0.097 m/s as the giver sets it down, ≤ 0.022 m/s at rest on
    /// the table, up to 0.69 m/s in the reach).
    pub reach_speed_m_s: f64,
    /// Grasp: the taker's force magnitude |F| exceeds this [N]. Default 5 (bundled recording:
    /// ≤ 0.8 N before the transfer, ≈ 30 N while the taker carries the baton).
    pub grasp_force_n: f64,
    /// Release: at or after the grasp, the giver's |F| falls below this [N]. Default 1
    /// (bundled recording: 15–23 N while the giver holds, 0.1–0.5 N after).
    pub release_force_n: f64,
    /// An explicit C(t) interval [start, end) [s] that replaces the derived one; an empty
    /// interval (start ≥ end) means C is never set. Default `None` (derive C from the data).
    pub collaboration_s: Option<(f64, f64)>,
}

impl Default for KthOptions {
    fn default() -> Self {
        Self {
            rate_hz: KTH_RATE_HZ,
            speed_window_s: 0.1,
            reach_speed_m_s: 0.2,
            grasp_force_n: 5.0,
            release_force_n: 1.0,
            collaboration_s: None,
        }
    }
}

/// The handover events detected in a recording (module docs, "Robot context").
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HandoverEvents {
    /// Reach onset: the baton starts to move toward the taker [s].
    pub reach_onset_s: Option<f64>,
    /// Grasp: the taker's force first exceeds `grasp_force_n` [s].
    pub grasp_s: Option<f64>,
    /// Release: the giver's force falls below `release_force_n`; the transfer is complete [s].
    pub release_s: Option<f64>,
    /// The taker's hand nearer to the baton at the release (or on the last row without one).
    pub receiving_hand: Option<Hand>,
}

/// A KTH handover folder, read for the taker.
#[derive(Debug, Clone, PartialEq)]
pub struct KthRecording {
    /// One frame per row, t = row / `rate_hz` [s].
    pub frames: Vec<CueFrame>,
    /// The detected events.
    pub events: HandoverEvents,
}

/// Reads the taker's cues and the derived robot context from a KTH handover folder.
pub fn read_taker(dir: &Path, opts: &KthOptions) -> Result<Vec<CueFrame>> {
    read_recording(dir, opts).map(|r| r.frames)
}

/// Reads the taker's cues, the robot context and the handover events from a KTH handover
/// folder. Reads `taker_{head,chest,LUArm,RUArm,LHand,RHand}_pose_saved.csv`,
/// `baton_pose_saved.csv` and `Wrench_{giver,taker}_saved.csv`.
pub fn read_recording(dir: &Path, opts: &KthOptions) -> Result<KthRecording> {
    validate(opts)?;
    let pose = |name: &str| read_table(&dir.join(format!("{name}_pose_saved.csv")), &POSE_HEADER);
    let head = pose("taker_head")?;
    let chest = pose("taker_chest")?;
    let l_uarm = pose("taker_LUArm")?;
    let r_uarm = pose("taker_RUArm")?;
    let l_hand = pose("taker_LHand")?;
    let r_hand = pose("taker_RHand")?;
    let baton = pose("baton")?;
    let wrench = |name: &str| {
        read_table(
            &dir.join(format!("Wrench_{name}_saved.csv")),
            &WRENCH_HEADER,
        )
    };
    let giver_f = wrench("giver")?;
    let taker_f = wrench("taker")?;

    let n = [&head, &chest, &l_uarm, &r_uarm, &l_hand, &r_hand, &baton]
        .iter()
        .map(|t| t.len())
        .max()
        .unwrap_or(0);
    let rows = Rows {
        head,
        chest,
        l_uarm,
        r_uarm,
        hands: [l_hand, r_hand],
        baton,
        giver_f,
        taker_f,
    };
    let (events, onset, release) = detect_events(&rows, n, opts);

    let mut frames = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64 / opts.rate_hz;
        let mut frame = CueFrame::empty(t);
        frame.head = rows.head.get(k).and_then(pose_of).map(|(x, q)| HeadCue {
            position: x,
            facing: rotate_xyzw(q, FACING_AXIS).unwrap_or(FACING_AXIS),
            confidence: 1.0,
        });
        frame.body = rows.chest.get(k).and_then(pose_of).map(|(x, q)| {
            let shoulders = position_of(&rows.l_uarm, k).zip(position_of(&rows.r_uarm, k));
            BodyCue {
                position: shoulders.map_or(x, |(l, r)| (l + r) / 2.0),
                facing: rotate_xyzw(q, FACING_AXIS).unwrap_or(FACING_AXIS),
                confidence: 1.0,
            }
        });
        for hand in Hand::BOTH {
            frame.hands[hand as usize] =
                position_of(&rows.hands[hand as usize], k).map(|x| HandCue {
                    position: x,
                    confidence: 1.0,
                });
        }
        let incomplete = release.is_none_or(|r| k < r);
        let collaborating = match opts.collaboration_s {
            Some((start, end)) => start <= t && t < end,
            None => onset.is_some_and(|o| o <= k) && incomplete,
        };
        frame.robot = RobotContext {
            collaborating,
            incomplete,
        };
        frames.push(frame);
    }
    Ok(KthRecording { frames, events })
}

/// Rotates `v` by the unit quaternion `q` given in the dataset's order `[x, y, z, w]` (scalar
/// last): R(q) v, body → world. Returns `None` when `q` is not finite or its norm is outside
/// [0.5, 2] (a lost rigid body); otherwise `q` is normalised first.
pub fn rotate_xyzw(q: [f64; 4], v: Vec3) -> Option<Vec3> {
    let [x, y, z, w] = q;
    let n = (x * x + y * y + z * z + w * w).sqrt();
    if !(n.is_finite() && (0.5..=2.0).contains(&n)) {
        return None;
    }
    let (x, y, z, w) = (x / n, y / n, z / n, w / n);
    // R(q) for the Hamilton quaternion w + xi + yj + zk.
    let r = [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ];
    Some(Vec3::new(
        r[0][0] * v.x + r[0][1] * v.y + r[0][2] * v.z,
        r[1][0] * v.x + r[1][1] * v.y + r[1][2] * v.z,
        r[2][0] * v.x + r[2][1] * v.y + r[2][2] * v.z,
    ))
}

fn validate(opts: &KthOptions) -> Result<()> {
    let positive = |key: &str, v: f64| {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(AssessError::invalid(
                key,
                format!("must be finite and > 0 (got {v})"),
            ))
        }
    };
    positive("kth.rate_hz", opts.rate_hz)?;
    positive("kth.speed_window_s", opts.speed_window_s)?;
    positive("kth.reach_speed_m_s", opts.reach_speed_m_s)?;
    positive("kth.grasp_force_n", opts.grasp_force_n)?;
    positive("kth.release_force_n", opts.release_force_n)?;
    if let Some((a, b)) = opts.collaboration_s
        && !(a.is_finite() && b.is_finite())
    {
        return Err(AssessError::invalid(
            "kth.collaboration_s",
            format!("must be finite (got [{a}, {b}))"),
        ));
    }
    Ok(())
}

/// One table's rows; a row is `None` when any of its values is missing or not finite.
type Table = Vec<Option<Vec<f64>>>;

struct Rows {
    head: Table,
    chest: Table,
    l_uarm: Table,
    r_uarm: Table,
    hands: [Table; 2],
    baton: Table,
    giver_f: Table,
    taker_f: Table,
}

/// Position and quaternion `[x, y, z, w]` of a pose row, when the quaternion is usable.
fn pose_of(row: &Option<Vec<f64>>) -> Option<(Vec3, [f64; 4])> {
    let r = row.as_ref()?;
    let q = [r[3], r[4], r[5], r[6]];
    rotate_xyzw(q, Vec3::x())?;
    Some((Vec3::new(r[0], r[1], r[2]), q))
}

fn position_of(table: &Table, k: usize) -> Option<Vec3> {
    pose_of(table.get(k)?).map(|(x, _)| x)
}

fn force_of(table: &Table, k: usize) -> Option<f64> {
    let r = table.get(k)?.as_ref()?;
    Some(Vec3::new(r[0], r[1], r[2]).norm())
}

/// The events, with the rows of the reach onset and the release.
fn detect_events(
    rows: &Rows,
    n: usize,
    opts: &KthOptions,
) -> (HandoverEvents, Option<usize>, Option<usize>) {
    let w = ((opts.speed_window_s * opts.rate_hz).round() as usize).max(1);
    let onset = (1..n).find(|&k| {
        let back = k.saturating_sub(w);
        let span = (k - back) as f64 / opts.rate_hz;
        match (position_of(&rows.baton, k), position_of(&rows.baton, back)) {
            (Some(a), Some(b)) => (a - b).norm() / span > opts.reach_speed_m_s,
            _ => false,
        }
    });
    let grasp =
        (0..n).find(|&k| force_of(&rows.taker_f, k).is_some_and(|f| f > opts.grasp_force_n));
    let release = grasp.and_then(|g| {
        (g..n).find(|&k| force_of(&rows.giver_f, k).is_some_and(|f| f < opts.release_force_n))
    });
    let at = release.unwrap_or(n.saturating_sub(1));
    let receiving_hand = position_of(&rows.baton, at).and_then(|b| {
        let d = |h: Hand| position_of(&rows.hands[h as usize], at).map(|p| (p - b).norm());
        match (d(Hand::Left), d(Hand::Right)) {
            (Some(l), Some(r)) => Some(if l < r { Hand::Left } else { Hand::Right }),
            (Some(_), None) => Some(Hand::Left),
            (None, Some(_)) => Some(Hand::Right),
            (None, None) => None,
        }
    });
    let t = |k: usize| k as f64 / opts.rate_hz;
    let events = HandoverEvents {
        reach_onset_s: onset.map(t),
        grasp_s: grasp.map(t),
        release_s: release.map(t),
        receiving_hand,
    };
    (events, onset, release)
}

/// Reads a CSV with the expected header. Empty or non-finite cells make the row `None`;
/// a wrong field count or an unparsable cell is an error with the line and column.
fn read_table(path: &Path, header: &[&str]) -> Result<Table> {
    let text = crate::error::read_text(path)?;
    let err = |line: usize, column: usize, message: String| AssessError::Csv {
        path: PathBuf::from(path),
        line: line as u64,
        column,
        message,
    };
    let mut lines = text.lines().map(|l| l.strip_suffix('\r').unwrap_or(l));
    let first = lines.next().unwrap_or("");
    let got: Vec<&str> = first.split(',').map(str::trim).collect();
    if got != header {
        return Err(err(
            1,
            1,
            format!(
                "expected the header `{}`, found `{first}`",
                header.join(",")
            ),
        ));
    }
    let body: Vec<&str> = lines.collect();
    // Trailing empty lines are not rows.
    let used = body
        .iter()
        .rposition(|l| !l.trim().is_empty())
        .map_or(0, |i| i + 1);
    let mut rows = Vec::with_capacity(used);
    for (i, line) in body.iter().take(used).enumerate() {
        let line_no = i + 2;
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != header.len() {
            return Err(err(
                line_no,
                1,
                format!("expected {} fields, found {}", header.len(), fields.len()),
            ));
        }
        let mut values = Vec::with_capacity(header.len());
        let mut complete = true;
        for (c, cell) in fields.iter().enumerate() {
            let cell = cell.trim();
            if cell.is_empty() {
                complete = false;
                continue;
            }
            let v: f64 = cell.parse().map_err(|_| {
                err(
                    line_no,
                    c + 1,
                    format!("column `{}`: `{cell}` is not a number", header[c]),
                )
            })?;
            complete &= v.is_finite();
            values.push(v);
        }
        rows.push(complete.then_some(values));
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_1_SQRT_2;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).norm() < 1e-12
    }

    #[test]
    fn quaternion_rotation_hand_computed() {
        // Identity [0, 0, 0, 1]: v unchanged.
        let v = Vec3::new(0.3, -0.2, 0.9);
        assert!(close(rotate_xyzw([0.0, 0.0, 0.0, 1.0], v).unwrap(), v));
        // 90° about z: (x, y, z, w) = (0, 0, sin 45°, cos 45°). x̂ → ŷ, ŷ → −x̂, so the
        // facing axis −ŷ → +x̂.
        let qz = [0.0, 0.0, FRAC_1_SQRT_2, FRAC_1_SQRT_2];
        assert!(close(rotate_xyzw(qz, Vec3::x()).unwrap(), Vec3::y()));
        assert!(close(rotate_xyzw(qz, FACING_AXIS).unwrap(), Vec3::x()));
        // 180° about x: (1, 0, 0, 0). ŷ → −ŷ, ẑ → −ẑ.
        assert!(close(
            rotate_xyzw([1.0, 0.0, 0.0, 0.0], Vec3::z()).unwrap(),
            -Vec3::z()
        ));
        // 120° about (1,1,1)/√3: (x, y, z, w) = (½, ½, ½, ½) cycles x̂ → ŷ → ẑ → x̂.
        let q = [0.5, 0.5, 0.5, 0.5];
        assert!(close(rotate_xyzw(q, Vec3::x()).unwrap(), Vec3::y()));
        assert!(close(rotate_xyzw(q, Vec3::y()).unwrap(), Vec3::z()));
        // Not normalised (norm 2): normalised first. Norm 0.1 or NaN: a lost body.
        assert!(close(rotate_xyzw([0.0, 0.0, 0.0, 2.0], v).unwrap(), v));
        assert!(rotate_xyzw([0.0, 0.0, 0.0, 0.1], v).is_none());
        assert!(rotate_xyzw([f64::NAN, 0.0, 0.0, 1.0], v).is_none());
    }

    #[test]
    fn quaternion_rotation_agrees_with_nalgebra() {
        // nalgebra's Quaternion::new takes (w, i, j, k): the scalar first.
        let (x, y, z, w) = (0.1023, 0.6197, -0.7723, -0.0947);
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        let v = Vec3::new(0.2, -1.0, 0.4);
        assert!(close(rotate_xyzw([x, y, z, w], v).unwrap(), q * v));
    }

    /// A unique scratch folder under the system temp dir.
    fn scratch(tag: &str) -> PathBuf {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static N: AtomicUsize = AtomicUsize::new(0);
        let dir = std::env::temp_dir().join(format!(
            "assess-kth-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    const IDENTITY: &str = "0,0,0,1";
    // 90° about z: the body's −y (facing) axis points along world +x.
    const YAW_90: &str = "0,0,0.7071067811865476,0.7071067811865476";

    /// Six rows at 10 Hz. The baton moves 0.05 m per row from row 2 on (0.5 m/s); the taker
    /// grips at row 3 (|F| = 6 N), the giver lets go at row 4 (|F| = 0.5 N).
    fn write_folder(dir: &Path, head_rows: &[&str]) {
        let pose = |name: &str, rows: Vec<String>| {
            let mut s = String::from("x,y,z,q0,q1,q2,q3\n");
            for r in rows {
                s.push_str(&r);
                s.push('\n');
            }
            std::fs::write(dir.join(format!("{name}_pose_saved.csv")), s).unwrap();
        };
        let still = |x: &str| {
            (0..6)
                .map(|_| format!("{x},{IDENTITY}"))
                .collect::<Vec<_>>()
        };
        pose(
            "taker_head",
            head_rows.iter().map(|s| s.to_string()).collect(),
        );
        pose(
            "taker_chest",
            (0..6).map(|_| format!("1,0,1.1,{YAW_90}")).collect(),
        );
        pose("taker_LUArm", still("1,0.2,1.3"));
        pose("taker_RUArm", still("1,-0.2,1.3"));
        pose("taker_LHand", still("0.9,0.3,0.8"));
        pose("taker_RHand", still("0.6,-0.1,1.0"));
        let baton_x = [0.0, 0.0, 0.05, 0.10, 0.15, 0.20];
        pose(
            "baton",
            baton_x
                .iter()
                .map(|x| format!("{x},0,1,{IDENTITY}"))
                .collect(),
        );
        let wrench = |name: &str, f: [f64; 6]| {
            let mut s = String::from("Fx,Fy,Fz,Tx,Ty,Tz\n");
            for v in f {
                s.push_str(&format!("0,0,{v},0,0,0\n"));
            }
            std::fs::write(dir.join(format!("Wrench_{name}_saved.csv")), s).unwrap();
        };
        wrench("taker", [0.1, 0.1, 0.2, 6.0, 8.0, 9.0]);
        wrench("giver", [9.0, 9.0, 9.0, 4.0, 0.5, 0.2]);
    }

    #[test]
    fn reads_a_tiny_folder() {
        let dir = scratch("tiny");
        let head = [
            format!("1,0,1.5,{YAW_90}"),
            format!("1,0,1.5,{YAW_90}"),
            // A lost head: empty cells, then NaN.
            ",,,,,,".to_string(),
            "1,0,1.5,NaN,0,0,1".to_string(),
            format!("1,0,1.5,{IDENTITY}"),
        ];
        write_folder(&dir, &head.iter().map(String::as_str).collect::<Vec<_>>());
        let opts = KthOptions {
            rate_hz: 10.0,
            ..KthOptions::default()
        };
        let rec = read_recording(&dir, &opts).unwrap();
        let f = &rec.frames;
        // Six rows (the head file has five: its sixth row is missing), t = k / 10 Hz.
        assert_eq!(f.len(), 6);
        assert!((f[5].t - 0.5).abs() < 1e-12);
        // Yawed 90°: the head faces +x.
        let h = f[0].head.unwrap();
        assert!(close(h.facing, Vec3::x()) && close(h.position, Vec3::new(1.0, 0.0, 1.5)));
        assert!(f[2].head.is_none() && f[3].head.is_none() && f[5].head.is_none());
        // Identity: the head faces −y.
        assert!(close(f[4].head.unwrap().facing, -Vec3::y()));
        // Body: the shoulder midpoint, facing the chest's −y (here +x).
        let b = f[0].body.unwrap();
        assert!(close(b.position, Vec3::new(1.0, 0.0, 1.3)) && close(b.facing, Vec3::x()));
        // Hands at their own index.
        assert!(close(
            f[0].hand(Hand::Left).unwrap().position,
            Vec3::new(0.9, 0.3, 0.8)
        ));
        assert!(close(
            f[0].hand(Hand::Right).unwrap().position,
            Vec3::new(0.6, -0.1, 1.0)
        ));
        // Baton speed over round(0.1 s · 10 Hz) = 1 row: 0.5 m/s from row 2 > 0.2 → onset 0.2 s.
        // Taker |F| 6 > 5 N at row 3 → grasp 0.3 s; giver 0.5 < 1 N at row 4 → release 0.4 s.
        assert_eq!(rec.events.reach_onset_s, Some(0.2));
        assert_eq!(rec.events.grasp_s, Some(0.3));
        assert_eq!(rec.events.release_s, Some(0.4));
        // At the release the right hand (0.6, −0.1, 1.0) is 0.46 m from the baton (0.15, 0, 1),
        // the left (0.9, 0.3, 0.8) 0.83 m.
        assert_eq!(rec.events.receiving_hand, Some(Hand::Right));
        let c: Vec<bool> = f.iter().map(|f| f.robot.collaborating).collect();
        let g: Vec<bool> = f.iter().map(|f| f.robot.incomplete).collect();
        assert_eq!(c, [false, false, true, true, false, false]);
        assert_eq!(g, [true, true, true, true, false, false]);

        // An explicit interval replaces C; G is unchanged.
        let opts = KthOptions {
            rate_hz: 10.0,
            collaboration_s: Some((0.05, 0.25)),
            ..KthOptions::default()
        };
        let frames = read_taker(&dir, &opts).unwrap();
        let c: Vec<bool> = frames.iter().map(|f| f.robot.collaborating).collect();
        assert_eq!(c, [false, true, true, false, false, false]);
        let g: Vec<bool> = frames.iter().map(|f| f.robot.incomplete).collect();
        assert_eq!(g, [true, true, true, true, false, false]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn malformed_rows_name_file_line_and_column() {
        let dir = scratch("bad");
        let ok = format!("1,0,1.5,{IDENTITY}");
        let bad_cell = format!("1,zero,1.5,{IDENTITY}");
        write_folder(&dir, &[&ok, &ok, &ok, &bad_cell, &ok, &ok]);
        let e = read_taker(&dir, &KthOptions::default()).unwrap_err();
        // Data row 3 (0-based) is line 5, after the header and rows 0–2; `zero` is column 2.
        match &e {
            AssessError::Csv {
                path, line, column, ..
            } => {
                assert!(path.ends_with("taker_head_pose_saved.csv"), "{e}");
                assert_eq!((*line, *column), (5, 2), "{e}");
            }
            other => panic!("expected a Csv error, got {other:?}"),
        }
        assert!(e.to_string().contains("`zero` is not a number"), "{e}");

        let short = "1,0,1.5,0,0,0";
        write_folder(&dir, &[ok.as_str(), short, ok.as_str()]);
        let e = read_taker(&dir, &KthOptions::default()).unwrap_err();
        assert!(
            matches!(&e, AssessError::Csv { line: 3, .. })
                && e.to_string().contains("expected 7 fields, found 6"),
            "{e}"
        );

        write_folder(&dir, &[&ok]);
        std::fs::write(dir.join("Wrench_giver_saved.csv"), "Fx,Fy,Fz\n0,0,0\n").unwrap();
        let e = read_taker(&dir, &KthOptions::default()).unwrap_err();
        assert!(
            matches!(&e, AssessError::Csv { line: 1, .. }) && e.to_string().contains("header"),
            "{e}"
        );

        std::fs::remove_file(dir.join("baton_pose_saved.csv")).unwrap();
        let e = read_taker(&dir, &KthOptions::default()).unwrap_err();
        assert!(
            matches!(&e, AssessError::Io { .. }) && e.to_string().contains("baton_pose_saved.csv"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
