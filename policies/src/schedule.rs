//! A/B schedule design: participants × conditions × policies, counterbalanced with a balanced
//! Latin square (Williams design), reproducible from a seed.
//!
//! # Design
//! - A **treatment** is one (condition, policy) cell; with L1–L3 × {fixed, adaptive} there are
//!   six. Each participant runs every treatment once (a fully within-subject design), so the
//!   order of all six is counterbalanced together: the condition order and the policy order,
//!   and the carry-over between any two cells, are balanced at once.
//! - The orders are the rows of a **Williams square** ([`williams_square`]) over the n
//!   treatments: every treatment appears once in each row and once in each column (position),
//!   and every treatment immediately follows every other treatment equally often (first-order
//!   carry-over balance). For even n the square has n rows; for odd n a single Latin square
//!   cannot be carry-over balanced, so the square is doubled with its mirror image (2n rows, each
//!   treatment twice per column, each ordered pair twice).
//! - **Randomisation from the seed**: (1) the treatments are assigned to the square's symbols by
//!   a random permutation (relabelling keeps every balance property); (2) participants are taken
//!   in blocks of as many participants as the square has rows, and each block gets the rows in
//!   a fresh random order. The balance is exact when the participant count is a multiple of the
//!   row count ([`Schedule::complete`]); otherwise the last block is a partial square and the
//!   schedule says so.
//! - **PRNG**: [`SplitMix64`] (Steele, Lea and Flood 2014, the seeder of Java's
//!   `SplittableRandom` and of xoshiro), written here so that the schedule of a seed never
//!   changes with a dependency's version. Bounded draws use rejection sampling, so shuffles are
//!   unbiased.
//!
//! ```
//! use policies::{Condition, ExperimentDesign};
//! let design = ExperimentDesign {
//!     participants: 12,
//!     conditions: Condition::ALL.to_vec(),
//!     policies: vec!["fixed".into(), "adaptive".into()],
//!     seed: 7,
//! };
//! let schedule = design.schedule()?;
//! assert_eq!(schedule.square_rows, 6);
//! assert!(schedule.complete);
//! assert_eq!(schedule.sessions[0].trials.len(), 6);
//! assert_eq!(schedule, design.schedule()?); // same seed, same schedule
//! # Ok::<(), policies::PolicyError>(())
//! ```

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::{PolicyError, Result};

/// SplitMix64, a 64-bit PRNG with a 64-bit state (Steele, Lea and Flood, "Fast splittable
/// pseudorandom number generators", OOPSLA 2014). Not cryptographic; used only to make
/// schedules reproducible from a seed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A generator seeded with `seed` (any value, including 0).
    pub fn new(seed: u64) -> SplitMix64 {
        SplitMix64 { state: seed }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A uniform integer in `0..n` (unbiased: draws below 2^64 mod n are rejected). `n` must
    /// be ≥ 1.
    pub fn below(&mut self, n: usize) -> usize {
        assert!(n >= 1, "SplitMix64::below(0)");
        let n = n as u64;
        let threshold = n.wrapping_neg() % n;
        loop {
            let x = self.next_u64();
            if x >= threshold {
                return (x % n) as usize;
            }
        }
    }

    /// Shuffles `items` in place (Fisher–Yates).
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            let j = self.below(i + 1);
            items.swap(i, j);
        }
    }
}

/// The rows of a Williams design over the symbols `0..n` (n ≥ 1).
///
/// Row 0 is 0, 1, n−1, 2, n−2, …; row i adds i modulo n to every entry. For even n that is an
/// n×n Latin square in which every ordered pair (a, b), a ≠ b, is adjacent exactly once. For
/// odd n the n reversed rows are appended, giving 2n rows in which every symbol appears twice
/// per column and every ordered pair is adjacent exactly twice. n = 1 gives `[[0]]`.
pub fn williams_square(n: usize) -> Vec<Vec<usize>> {
    let first: Vec<usize> = (0..n)
        .map(|j| {
            if j % 2 == 1 {
                j.div_ceil(2)
            } else {
                (n - j / 2) % n
            }
        })
        .collect();
    let mut rows: Vec<Vec<usize>> = (0..n)
        .map(|i| first.iter().map(|&s| (s + i) % n).collect())
        .collect();
    if n % 2 == 1 && n > 1 {
        let mirrored: Vec<Vec<usize>> = rows
            .iter()
            .map(|r| r.iter().rev().copied().collect())
            .collect();
        rows.extend(mirrored);
    }
    rows
}

/// The task difficulty level of the paper's gearbox task.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Condition {
    /// The robot delivers one component.
    L1,
    /// Two components and a screwdriver.
    L2,
    /// Two components and a fastening module (screwdriver and screws).
    L3,
}

impl Condition {
    /// L1, L2, L3.
    pub const ALL: [Condition; 3] = [Condition::L1, Condition::L2, Condition::L3];

    /// `L1`, `L2` or `L3`.
    pub fn as_str(self) -> &'static str {
        match self {
            Condition::L1 => "L1",
            Condition::L2 => "L2",
            Condition::L3 => "L3",
        }
    }
}

impl fmt::Display for Condition {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One cell of the design: a condition run with a policy.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Treatment {
    /// The task level.
    pub condition: Condition,
    /// The policy's name (`fixed`, `adaptive`).
    pub policy: String,
}

/// The most participants a design may have: 1000, far more than a lab study runs; it bounds
/// the schedule's allocation (issue 10: a huge count passed and aborted the process).
pub const MAX_PARTICIPANTS: usize = 1000;

/// What to schedule.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExperimentDesign {
    /// Number of participants, in [1, [`MAX_PARTICIPANTS`]]; they are named `P01`, `P02`, ….
    pub participants: usize,
    /// The conditions (non-empty, no repeats).
    pub conditions: Vec<Condition>,
    /// The policy names (non-empty, no repeats, none empty).
    pub policies: Vec<String>,
    /// The randomisation seed.
    pub seed: u64,
}

/// One participant's order of treatments.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Session {
    /// The participant's id (`P01`, …).
    pub participant: String,
    /// Which row of the Williams square gives the order (0-based).
    pub square_row: usize,
    /// The treatments in running order.
    pub trials: Vec<Treatment>,
}

/// One trial of the schedule, flat, for CSV.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ScheduledTrial {
    /// The participant's id.
    pub participant: String,
    /// 1-based position in the participant's session.
    pub position: usize,
    /// The task level.
    pub condition: Condition,
    /// The policy's name.
    pub policy: String,
    /// The Williams square row of the session (0-based).
    pub square_row: usize,
}

/// A counterbalanced schedule (serialisable; the binary writes it as CSV via
/// [`Schedule::trials`] or as JSON whole).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Schedule {
    /// The seed it was drawn from.
    pub seed: u64,
    /// The treatments, indexed by the square's symbols (after the random relabelling).
    pub treatments: Vec<Treatment>,
    /// Rows of the Williams square: n for even n treatments, 2n for odd n.
    pub square_rows: usize,
    /// Whether the participant count is a multiple of `square_rows` (exact balance).
    pub complete: bool,
    /// One session per participant, in participant order.
    pub sessions: Vec<Session>,
}

impl ExperimentDesign {
    /// Draws the schedule (see the module docs).
    pub fn schedule(&self) -> Result<Schedule> {
        let invalid = |reason: String| Err(PolicyError::InvalidDesign { reason });
        if self.participants == 0 {
            return invalid("no participants".into());
        }
        if self.participants > MAX_PARTICIPANTS {
            return invalid(format!(
                "participants must be at most {MAX_PARTICIPANTS}, got {}",
                self.participants
            ));
        }
        if self.conditions.is_empty() {
            return invalid("no conditions".into());
        }
        if self.policies.is_empty() {
            return invalid("no policies".into());
        }
        for (i, c) in self.conditions.iter().enumerate() {
            if self.conditions[..i].contains(c) {
                return invalid(format!("condition {c} is listed twice"));
            }
        }
        for (i, p) in self.policies.iter().enumerate() {
            if p.trim().is_empty() {
                return invalid("a policy name is empty".into());
            }
            if self.policies[..i].contains(p) {
                return invalid(format!("policy `{p}` is listed twice"));
            }
        }

        let mut rng = SplitMix64::new(self.seed);
        let mut treatments: Vec<Treatment> = self
            .conditions
            .iter()
            .flat_map(|&condition| {
                self.policies.iter().map(move |p| Treatment {
                    condition,
                    policy: p.clone(),
                })
            })
            .collect();
        rng.shuffle(&mut treatments);
        let square = williams_square(treatments.len());
        let rows = square.len();

        let width = self.participants.to_string().len().max(2);
        let mut sessions = Vec::with_capacity(self.participants);
        let mut order: Vec<usize> = Vec::new();
        for p in 0..self.participants {
            if p % rows == 0 {
                order = (0..rows).collect();
                rng.shuffle(&mut order);
            }
            let row = order[p % rows];
            sessions.push(Session {
                participant: format!("P{:0width$}", p + 1),
                square_row: row,
                trials: square[row].iter().map(|&s| treatments[s].clone()).collect(),
            });
        }
        Ok(Schedule {
            seed: self.seed,
            treatments,
            square_rows: rows,
            complete: self.participants.is_multiple_of(rows),
            sessions,
        })
    }
}

impl Schedule {
    /// Every trial, session by session, in running order (the CSV rows).
    pub fn trials(&self) -> Vec<ScheduledTrial> {
        self.sessions
            .iter()
            .flat_map(|s| {
                s.trials
                    .iter()
                    .enumerate()
                    .map(move |(i, t)| ScheduledTrial {
                        participant: s.participant.clone(),
                        position: i + 1,
                        condition: t.condition,
                        policy: t.policy.clone(),
                        square_row: s.square_row,
                    })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    #[test]
    fn participants_are_bounded_at_1000() {
        let design = |participants| ExperimentDesign {
            participants,
            conditions: vec![Condition::L1],
            policies: vec!["adaptive".into(), "fixed".into()],
            seed: 1,
        };
        assert_eq!(design(1000).schedule().unwrap().sessions.len(), 1000);
        // usize::MAX passed at a077dd5 and panicked allocating the sessions (issue 10).
        for bad in [1001, usize::MAX] {
            let e = design(bad).schedule().unwrap_err().to_string();
            assert!(e.contains("participants must be at most 1000"), "{e}");
        }
    }

    /// Checks the Williams properties of `rows` over `0..n`: Latin rows, every column holding
    /// each symbol `reps` times, every ordered pair adjacent `reps` times.
    fn assert_williams(rows: &[Vec<usize>], n: usize) {
        assert_balanced(rows, n);
        // For odd n each half of the square, in its own row order, is itself a Latin square
        // (each symbol once per column).
        if n % 2 == 1 && n > 1 {
            for half in rows.chunks(n) {
                for col in 0..n {
                    let mut seen: Vec<usize> = half.iter().map(|r| r[col]).collect();
                    seen.sort_unstable();
                    assert_eq!(seen, (0..n).collect::<Vec<_>>());
                }
            }
        }
    }

    /// The balance properties that survive any reordering of the rows.
    fn assert_balanced(rows: &[Vec<usize>], n: usize) {
        let reps = if n % 2 == 1 && n > 1 { 2 } else { 1 };
        assert_eq!(rows.len(), reps * n, "n = {n}");
        for r in rows {
            let mut seen = r.clone();
            seen.sort_unstable();
            assert_eq!(
                seen,
                (0..n).collect::<Vec<_>>(),
                "row {r:?} is not a permutation"
            );
        }
        for col in 0..n {
            let mut count = vec![0; n];
            for r in rows {
                count[r[col]] += 1;
            }
            assert!(
                count.iter().all(|&c| c == reps),
                "n = {n}, column {col}: {count:?}"
            );
        }
        let mut pairs: HashMap<(usize, usize), usize> = HashMap::new();
        for r in rows {
            for w in r.windows(2) {
                *pairs.entry((w[0], w[1])).or_default() += 1;
            }
        }
        for a in 0..n {
            for b in 0..n {
                let c = pairs.get(&(a, b)).copied().unwrap_or(0);
                let want = if a == b { 0 } else { reps };
                assert_eq!(c, want, "n = {n}: {a} → {b} follows {c} times, want {want}");
            }
        }
    }

    #[test]
    fn williams_squares_are_latin_and_carry_over_balanced() {
        for n in [2, 3, 4, 6] {
            assert_williams(&williams_square(n), n);
        }
        // And beyond the required sizes.
        for n in 1..=12 {
            assert_williams(&williams_square(n), n);
        }
    }

    #[test]
    fn williams_square_of_four_is_the_textbook_one() {
        assert_eq!(
            williams_square(4),
            vec![
                vec![0, 1, 3, 2],
                vec![1, 2, 0, 3],
                vec![2, 3, 1, 0],
                vec![3, 0, 2, 1]
            ]
        );
    }

    #[test]
    fn splitmix64_matches_the_reference_sequence() {
        // Reference outputs of SplitMix64 seeded with 0 (Vigna's splitmix64.c).
        let mut r = SplitMix64::new(0);
        assert_eq!(r.next_u64(), 0xe220_a839_7b1d_cdaf);
        assert_eq!(r.next_u64(), 0x6e78_9e6a_a1b9_65f4);
        assert_eq!(r.next_u64(), 0x06c4_5d18_8009_454f);
    }

    #[test]
    fn bounded_draws_are_in_range_and_cover_it() {
        let mut r = SplitMix64::new(42);
        let mut count = [0usize; 6];
        for _ in 0..6000 {
            count[r.below(6)] += 1;
        }
        // Each face ~1000; a 6-sigma band (σ ≈ 29) is generous and still catches a bias.
        assert!(count.iter().all(|&c| (820..1180).contains(&c)), "{count:?}");
    }

    fn design(participants: usize, policies: &[&str], seed: u64) -> ExperimentDesign {
        ExperimentDesign {
            participants,
            conditions: Condition::ALL.to_vec(),
            policies: policies.iter().map(|s| s.to_string()).collect(),
            seed,
        }
    }

    /// The schedule's sessions, as symbol rows (via the treatment list).
    fn as_rows(s: &Schedule) -> Vec<Vec<usize>> {
        s.sessions
            .iter()
            .map(|sess| {
                sess.trials
                    .iter()
                    .map(|t| s.treatments.iter().position(|u| u == t).unwrap())
                    .collect()
            })
            .collect()
    }

    #[test]
    fn a_complete_schedule_is_balanced_per_block() {
        // 3 conditions × 2 policies = 6 treatments, 12 participants = 2 full squares.
        let s = design(12, &["fixed", "adaptive"], 2024).schedule().unwrap();
        assert_eq!(s.treatments.len(), 6);
        assert_eq!(s.square_rows, 6);
        assert!(s.complete);
        let rows = as_rows(&s);
        for block in rows.chunks(6) {
            assert_williams(block, 6);
        }
        // Within a block, each participant has a different row.
        let mut used: Vec<usize> = s.sessions[..6].iter().map(|x| x.square_row).collect();
        used.sort_unstable();
        assert_eq!(used, (0..6).collect::<Vec<_>>());
        // Every participant runs every (condition, policy) once.
        for sess in &s.sessions {
            for c in Condition::ALL {
                for p in ["fixed", "adaptive"] {
                    let n = sess
                        .trials
                        .iter()
                        .filter(|t| t.condition == c && t.policy == p)
                        .count();
                    assert_eq!(n, 1, "{} {c} {p}", sess.participant);
                }
            }
        }
    }

    #[test]
    fn an_odd_number_of_treatments_uses_the_doubled_square() {
        // 3 conditions × 1 policy = 3 treatments → 6 rows.
        let s = design(6, &["adaptive"], 1).schedule().unwrap();
        assert_eq!(s.square_rows, 6);
        assert!(s.complete);
        // The six participants got the six rows in a shuffled order: the balance holds.
        assert_balanced(&as_rows(&s), 3);
    }

    #[test]
    fn an_incomplete_schedule_says_so() {
        let s = design(8, &["fixed", "adaptive"], 3).schedule().unwrap();
        assert!(!s.complete);
        assert_eq!(s.sessions.len(), 8);
        assert_eq!(s.sessions[7].participant, "P08");
        // The first six still form a full square.
        assert_williams(&as_rows(&s)[..6], 6);
        // The two extra sessions use two different rows.
        assert_ne!(s.sessions[6].square_row, s.sessions[7].square_row);
    }

    #[test]
    fn the_seed_decides_the_schedule() {
        let a = design(12, &["fixed", "adaptive"], 99).schedule().unwrap();
        assert_eq!(
            a,
            design(12, &["fixed", "adaptive"], 99).schedule().unwrap()
        );
        let differ = (100..110)
            .filter(|&seed| design(12, &["fixed", "adaptive"], seed).schedule().unwrap() != a)
            .count();
        assert_eq!(differ, 10, "other seeds should give other schedules");
    }

    #[test]
    fn schedules_serialise_and_round_trip() {
        let s = design(6, &["fixed", "adaptive"], 5).schedule().unwrap();
        let text = toml::to_string(&s).unwrap();
        let back: Schedule = toml::from_str(&text).unwrap();
        assert_eq!(back, s);
        let trials = s.trials();
        assert_eq!(trials.len(), 36);
        assert_eq!(trials[0].position, 1);
        assert_eq!(trials[5].position, 6);
        assert_eq!(trials[6].participant, "P02");
        let cell = toml::Value::try_from(&trials[0]).unwrap();
        assert!(matches!(
            cell["condition"].as_str(),
            Some("L1" | "L2" | "L3")
        ));
    }

    #[test]
    fn invalid_designs_are_errors() {
        let mut d = design(0, &["fixed"], 0);
        assert!(
            d.schedule()
                .unwrap_err()
                .to_string()
                .contains("no participants")
        );
        d.participants = 2;
        d.policies = vec!["fixed".into(), "fixed".into()];
        assert!(
            d.schedule()
                .unwrap_err()
                .to_string()
                .contains("`fixed` is listed twice")
        );
        d.policies = vec![];
        assert!(
            d.schedule()
                .unwrap_err()
                .to_string()
                .contains("no policies")
        );
    }
}
