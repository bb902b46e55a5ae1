//! `ReplayRobot`: a [`Robot`] that plays a recorded [`Trace`].
//!
//! Two pacings ([`Pacing`]):
//! - [`Pacing::PerRead`] (default): each `read_state` returns the next row, so every recorded
//!   sample is seen exactly once whatever the caller's rate.
//! - [`Pacing::Clocked`]: a mock clock starts at the first row's timestamp and advances
//!   `period_s` per `read_state`; each read returns the last row recorded at or before the
//!   clock (sample and hold, no interpolation). `timestamp_s` is the held row's recorded
//!   timestamp, so a held sample repeats its timestamp as a real controller's would not; a
//!   caller that needs a clock can use [`ReplayRobot::clock_s`].
//!
//! Fields the trace lacks keep their [`RobotState::default`] values (e.g. `safety_mode` NORMAL
//! when the recipe had no safety field). Reading past the end returns
//! [`RobotIoError::TraceEnded`] and sets [`ReplayRobot::is_finished`]; [`ReplayRobot::rewind`]
//! starts over.
//!
//! `send` moves nothing: it records the commands into a buffer preallocated at construction
//! (for tests to inspect) and, once that is full, only counts them, so it never allocates.

use crate::trace::Trace;
use crate::types::{JointCommand, Robot, RobotState};
use crate::{Result, RobotIoError};

/// Commands a [`ReplayRobot::new`] keeps by default.
pub const DEFAULT_COMMAND_CAPACITY: usize = 4096;

/// How a [`ReplayRobot`] advances through its trace.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Pacing {
    /// One row per `read_state`.
    #[default]
    PerRead,
    /// A mock clock advancing `period_s` \[s\] per `read_state`, holding the last recorded row.
    Clocked {
        /// Clock advance per read \[s\], finite and > 0 (0.002 for 500 Hz).
        period_s: f64,
    },
}

/// Plays a [`Trace`] through the [`Robot`] trait (see the module docs).
#[derive(Debug, Clone)]
pub struct ReplayRobot {
    trace: Trace,
    pacing: Pacing,
    /// Reads served so far since the last rewind.
    reads: u64,
    /// Next row for `PerRead`.
    next_row: usize,
    finished: bool,
    state: RobotState,
    commands: Vec<JointCommand>,
    commands_received: u64,
}

impl ReplayRobot {
    /// Replay `trace` one row per read, keeping up to [`DEFAULT_COMMAND_CAPACITY`] commands.
    pub fn new(trace: Trace) -> Self {
        Self {
            trace,
            pacing: Pacing::PerRead,
            reads: 0,
            next_row: 0,
            finished: false,
            state: RobotState::default(),
            commands: Vec::with_capacity(DEFAULT_COMMAND_CAPACITY),
            commands_received: 0,
        }
    }

    /// Replay `trace` with the given pacing, keeping up to `command_capacity` received commands.
    ///
    /// # Errors
    /// [`RobotIoError::InvalidSimConfig`] if a clocked period is not finite and > 0.
    pub fn with_pacing(trace: Trace, pacing: Pacing, command_capacity: usize) -> Result<Self> {
        if let Pacing::Clocked { period_s } = pacing
            && !(period_s.is_finite() && period_s > 0.0)
        {
            return Err(RobotIoError::InvalidSimConfig {
                field: "period_s",
                reason: "must be finite and > 0",
            });
        }
        let mut robot = Self::new(trace);
        robot.pacing = pacing;
        robot.commands = Vec::with_capacity(command_capacity);
        Ok(robot)
    }

    /// The trace being replayed.
    pub fn trace(&self) -> &Trace {
        &self.trace
    }

    /// The pacing.
    pub fn pacing(&self) -> Pacing {
        self.pacing
    }

    /// Whether a read has gone past the end of the trace.
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// Reads served since construction or the last rewind.
    pub fn reads(&self) -> u64 {
        self.reads
    }

    /// The clocked pacing's time for the next read \[s\] (the first row's timestamp plus
    /// `reads × period_s`); with `PerRead`, the next row's timestamp. `None` when the trace is
    /// empty or, per read, finished.
    pub fn clock_s(&self) -> Option<f64> {
        match self.pacing {
            Pacing::PerRead => self.trace.timestamp(self.next_row),
            Pacing::Clocked { period_s } => {
                Some(self.trace.timestamp(0)? + self.reads as f64 * period_s)
            }
        }
    }

    /// Start again from the first row; keeps the recorded commands.
    pub fn rewind(&mut self) {
        self.reads = 0;
        self.next_row = 0;
        self.finished = false;
        self.state = RobotState::default();
    }

    /// The commands received, up to the capacity, in order.
    pub fn commands(&self) -> &[JointCommand] {
        &self.commands
    }

    /// All commands received, including those past the capacity.
    pub fn commands_received(&self) -> u64 {
        self.commands_received
    }

    fn ended(&mut self) -> RobotIoError {
        self.finished = true;
        RobotIoError::TraceEnded {
            rows: self.trace.len(),
        }
    }
}

impl Robot for ReplayRobot {
    /// Fill `out` from the next row (or the row in force at the mock clock).
    ///
    /// # Implementation
    /// Never blocks, allocates nothing. Past the end: [`RobotIoError::TraceEnded`].
    fn read_state(&mut self, out: &mut RobotState) -> Result<()> {
        let row = match self.pacing {
            Pacing::PerRead => self.next_row,
            Pacing::Clocked { .. } => {
                let last = self
                    .trace
                    .len()
                    .checked_sub(1)
                    .and_then(|r| self.trace.timestamp(r));
                match (self.clock_s(), last) {
                    (Some(t), Some(last)) if t <= last => {
                        self.trace.row_at_time(t).unwrap_or_default()
                    }
                    _ => return Err(self.ended()),
                }
            }
        };
        if row >= self.trace.len() {
            return Err(self.ended());
        }
        self.trace.fill_state(row, &mut self.state)?;
        *out = self.state;
        self.next_row = row + 1;
        self.reads = self.reads.saturating_add(1);
        Ok(())
    }

    /// Record `cmd`; nothing moves.
    ///
    /// # Implementation
    /// Never blocks, never fails, allocates nothing (commands past the capacity are only
    /// counted).
    fn send(&mut self, cmd: &JointCommand) -> Result<()> {
        if self.commands.len() < self.commands.capacity() {
            self.commands.push(*cmd);
        }
        self.commands_received = self.commands_received.saturating_add(1);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::{runtime_state, safety_mode};
    use std::path::Path;

    fn rad_segment() -> Trace {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../data/rtde-traces/ur3e_25hz_rad_segment_L2L3.csv");
        Trace::read(path).unwrap()
    }

    #[test]
    fn per_read_plays_every_recorded_row_then_ends() {
        let trace = rad_segment();
        let rows = trace.len();
        let mut robot = ReplayRobot::new(trace.clone());
        let mut state = RobotState::default();
        let mut expected = RobotState::default();
        let mut saw_stopped = false;
        for r in 0..rows {
            robot.read_state(&mut state).unwrap();
            trace.fill_state(r, &mut expected).unwrap();
            assert_eq!(state, expected, "row {r}");
            assert_eq!(Some(state.actual_q[0]), trace.value(r, "actual_q_0"));
            saw_stopped |= state.runtime_state == runtime_state::STOPPED;
        }
        assert!(
            saw_stopped,
            "this recording has the program stopped for a while"
        );
        assert!(!robot.is_finished());
        let err = robot.read_state(&mut state).unwrap_err();
        assert!(matches!(err, RobotIoError::TraceEnded { rows: r } if r == rows));
        assert_eq!(
            err.to_string(),
            format!("the replayed trace ended after {rows} rows")
        );
        assert!(robot.is_finished());
        robot.rewind();
        robot.read_state(&mut state).unwrap();
        assert_eq!(Some(state.timestamp_s), trace.timestamp(0));
    }

    #[test]
    fn clocked_pacing_holds_samples_at_the_requested_rate() {
        // A 25 Hz recording read at 500 Hz: each sample is held for 20 reads.
        let trace = rad_segment();
        let rows = trace.len();
        let mut robot =
            ReplayRobot::with_pacing(trace.clone(), Pacing::Clocked { period_s: 0.002 }, 0)
                .unwrap();
        let mut state = RobotState::default();
        let mut reads = 0;
        let mut changes = 0;
        let mut last_ts = f64::NAN;
        while robot.read_state(&mut state).is_ok() {
            if state.timestamp_s != last_ts {
                changes += 1;
                last_ts = state.timestamp_s;
            }
            reads += 1;
        }
        assert_eq!(changes, rows, "every recorded sample was shown");
        let span = trace.timestamp(rows - 1).unwrap() - trace.timestamp(0).unwrap();
        let expected_reads = (span / 0.002).round() as i64 + 1;
        assert!(
            (reads - expected_reads).abs() <= 1,
            "{reads} vs {expected_reads}"
        );
        assert_eq!(Some(last_ts), trace.timestamp(rows - 1));
        assert!(robot.is_finished());
        assert!(ReplayRobot::with_pacing(trace, Pacing::Clocked { period_s: 0.0 }, 0).is_err());
    }

    #[test]
    fn injected_protective_stop_is_replayed_and_missing_fields_keep_defaults() {
        // A simulated trace without safety fields, with a protective stop injected in row 1.
        let mut trace = Trace::new(["timestamp", "actual_q_0", "safety_mode"]).unwrap();
        trace.push_row(&[0.0, 0.1, 1.0]).unwrap();
        trace.push_row(&[0.002, 0.1, 1.0]).unwrap();
        trace
            .set_value(1, "safety_mode", f64::from(safety_mode::PROTECTIVE_STOP))
            .unwrap();
        let mut robot = ReplayRobot::new(trace);
        let mut state = RobotState::default();
        robot.read_state(&mut state).unwrap();
        assert!(!state.is_safety_stopped());
        assert_eq!(state.runtime_state, runtime_state::PLAYING, "default kept");
        robot.read_state(&mut state).unwrap();
        assert!(state.is_safety_stopped());
    }

    #[test]
    fn send_records_commands_without_moving() {
        let trace = rad_segment();
        let mut robot = ReplayRobot::with_pacing(trace, Pacing::PerRead, 2).unwrap();
        let mut before = RobotState::default();
        robot.read_state(&mut before).unwrap();
        let cmds = [
            JointCommand::Stop { decel: 1.0 },
            JointCommand::Speed {
                qd: [0.1; 6],
                acc: 1.0,
            },
            JointCommand::Stop { decel: 2.0 },
        ];
        for c in &cmds {
            robot.send(c).unwrap();
        }
        assert_eq!(robot.commands(), &cmds[..2], "kept up to the capacity");
        assert_eq!(robot.commands_received(), 3);
        let mut after = RobotState::default();
        robot.read_state(&mut after).unwrap();
        assert_eq!(
            Some(after.actual_q[0]),
            robot.trace().value(1, "actual_q_0")
        );
    }
}
