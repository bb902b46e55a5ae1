//! Recorded RTDE traces: reading and writing the CSV files UR's and ur_rtde's clients produce.
//!
//! # Formats read (autodetected from the header line)
//! - **ur_rtde** (`RTDEReceiveInterface::startFileRecording`): comma-separated, `timestamp` first.
//! - **UR `record.py`**: separated by spaces (any run of spaces or tabs), `timestamp` first.
//! - **Extra leading columns**, as in the RAD data set (`time,_id,timestamp,…`): every column before
//!   `timestamp` is kept verbatim as text ([`Trace::leading_names`], [`Trace::leading_value`]);
//!   the RTDE fields are `timestamp` and every column after it.
//!
//! A header containing a comma selects the comma dialect, otherwise the space dialect. Lines may
//! end in LF, CRLF or a lone CR (all three occur in real recordings); blank lines are skipped; a
//! UTF-8 byte-order mark is ignored. Vector fields appear expanded, as in both clients:
//! `actual_q_0 … actual_q_5`.
//!
//! # Storage and exactness
//! Values are stored as `f64` in one row-major `Vec<f64>`, with a name → column index. Parsing is
//! correctly rounded, so every decimal text maps to the nearest `f64`, and writing with
//! [`FloatFormat::RoundTrip`] (shortest round-trip text) reads back bit-identical, including
//! `-0.0`, infinities and NaN.
//!
//! Integer fields (UINT8, UINT32, INT32, the bits fields, and UINT64 such as
//! `actual_digital_input_bits`) are exact in an `f64` up to 2^53 in magnitude. An integer token
//! (optional sign and digits only) larger than 2^53 is **rejected** with
//! [`TraceParseErrorKind::IntegerTooLarge`] instead of being silently rounded; real UINT64 bit
//! fields use far fewer than 53 bits.
//!
//! # Duplicates and gaps
//! Asynchronous clients record some controller cycles twice and skip others. Reading drops every
//! row whose `timestamp` equals the previous row's (keeping the first) and counts it; a
//! timestamp that decreases is an error. [`Trace::report`] estimates the nominal period (the
//! lower median of the positive timestamp steps) and lists the gaps: steps longer than 1.5 nominal
//! periods.
//!
//! # Example
//! ```
//! use robot_io::trace::Trace;
//! // Simulated 500 Hz samples: one repeated, then two cycles missing.
//! let text = "timestamp actual_q_0 runtime_state\n\
//!             0.0 0.5 2\n0.002 0.5 2\n0.002 0.5 2\n0.004 0.5 2\n0.010 0.6 2\n";
//! let trace = Trace::parse(text, "example.csv")?;
//! assert_eq!(trace.len(), 4);
//! assert_eq!(trace.value(3, "actual_q_0"), Some(0.6));
//! let report = trace.report();
//! assert_eq!(report.duplicates_removed, 1);
//! assert_eq!(report.gaps[0].missing_periods, 2);
//! # Ok::<(), robot_io::RobotIoError>(())
//! ```

use std::collections::HashMap;
use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::types::RobotState;
use crate::{Result, RobotIoError};

/// Largest integer magnitude an `f64` holds exactly: 2^53.
const MAX_EXACT_INTEGER: u128 = 1 << 53;

/// What is wrong at a line and column of a trace file (see [`RobotIoError::TraceParse`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TraceParseErrorKind {
    /// The file holds no header line.
    #[error("the file is empty")]
    Empty,
    /// The file is not valid UTF-8.
    #[error("the file is not valid utf-8")]
    NotUtf8,
    /// The header has no `timestamp` column.
    #[error("the header has no `timestamp` column")]
    MissingTimestamp,
    /// A column name appears twice in the header.
    #[error("column `{name}` appears twice in the header")]
    DuplicateColumn {
        /// The repeated name.
        name: String,
    },
    /// A column name is empty.
    #[error("empty column name in the header")]
    EmptyColumnName,
    /// A data line has a different number of columns from the header.
    #[error("expected {expected} columns, found {found}")]
    ColumnCount {
        /// Columns in the header.
        expected: usize,
        /// Columns in this line.
        found: usize,
    },
    /// A value is not a number.
    #[error("field `{field}`: `{text}` is not a number")]
    NotANumber {
        /// The column's name.
        field: String,
        /// The offending text.
        text: String,
    },
    /// An integer too large to be held exactly in an `f64` (above 2^53 in magnitude).
    #[error("field `{field}`: integer `{text}` exceeds 2^53 and cannot be stored exactly")]
    IntegerTooLarge {
        /// The column's name.
        field: String,
        /// The offending text.
        text: String,
    },
    /// A timestamp that is NaN or infinite.
    #[error("timestamp `{text}` is not finite")]
    TimestampNotFinite {
        /// The offending text.
        text: String,
    },
    /// A timestamp smaller than the one before it.
    #[error("timestamp {found} s goes back from {previous} s")]
    TimestampDecreasing {
        /// The previous row's timestamp \[s\].
        previous: f64,
        /// This row's timestamp \[s\].
        found: f64,
    },
}

/// The column separator of a trace file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Dialect {
    /// Commas, as written by ur_rtde's `startFileRecording`.
    #[default]
    Comma,
    /// Single spaces, as written by UR's `record.py`.
    Space,
}

impl Dialect {
    fn separator(self) -> &'static str {
        match self {
            Dialect::Comma => ",",
            Dialect::Space => " ",
        }
    }
}

/// How writers print values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FloatFormat {
    /// Shortest text that reads back to the identical `f64` (bit-exact round trip). Integral
    /// values below 2^53 print without a decimal point (`7`, not `7.0`).
    #[default]
    RoundTrip,
    /// A fixed number of decimals, as ur_rtde writes (it uses 6); lossy. Integers print with
    /// decimals too (`2.000000`), which UR's `csv_reader.py` does not match when it filters on
    /// `runtime_state == "2"` (a string comparison); prefer [`FloatFormat::RoundTrip`].
    Fixed(u8),
}

/// Options of the trace writers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WriteOptions {
    /// Column separator.
    pub dialect: Dialect,
    /// Number format.
    pub float_format: FloatFormat,
}

impl WriteOptions {
    /// ur_rtde's dialect (commas) with bit-exact round-trip numbers.
    pub fn ur_rtde() -> Self {
        Self {
            dialect: Dialect::Comma,
            float_format: FloatFormat::RoundTrip,
        }
    }

    /// UR `record.py`'s dialect (spaces) with bit-exact round-trip numbers.
    pub fn record_py() -> Self {
        Self {
            dialect: Dialect::Space,
            float_format: FloatFormat::RoundTrip,
        }
    }
}

/// A missing stretch of controller cycles between two consecutive rows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gap {
    /// The row (0-based, after de-duplication) the gap follows.
    pub after_row: usize,
    /// The timestamp of that row \[s\].
    pub after_timestamp: f64,
    /// The step to the next row \[s\].
    pub duration_s: f64,
    /// Nominal periods missing: `round(duration_s / nominal_period_s) - 1`, at least 1.
    pub missing_periods: u64,
}

/// What reading a trace found: duplicates dropped and gaps.
#[derive(Debug, Clone, PartialEq)]
pub struct TraceReport {
    /// Rows kept.
    pub rows: usize,
    /// Rows dropped because their timestamp repeated the previous row's.
    pub duplicates_removed: usize,
    /// The lower median of the positive steps between timestamps \[s\]; `None` with fewer than two rows.
    pub nominal_period_s: Option<f64>,
    /// Steps longer than 1.5 nominal periods, in order.
    pub gaps: Vec<Gap>,
}

impl TraceReport {
    /// Total missing cycles over all gaps.
    pub fn missing_periods(&self) -> u64 {
        self.gaps.iter().map(|g| g.missing_periods).sum()
    }
}

/// Column indices of the fields [`Trace::fill_state`] copies.
#[derive(Debug, Clone, Default)]
struct StateColumns {
    actual_q: [Option<usize>; 6],
    actual_qd: [Option<usize>; 6],
    target_q: [Option<usize>; 6],
    target_qd: [Option<usize>; 6],
    tcp_pose: [Option<usize>; 6],
    tcp_speed: [Option<usize>; 6],
    speed_scaling: Option<usize>,
    target_speed_fraction: Option<usize>,
    robot_mode: Option<usize>,
    safety_mode: Option<usize>,
    runtime_state: Option<usize>,
    robot_status_bits: Option<usize>,
    safety_status_bits: Option<usize>,
}

impl StateColumns {
    fn new(index: &HashMap<String, usize>) -> Self {
        let one = |name: &str| index.get(name).copied();
        let six = |base: &str| {
            let mut out = [None; 6];
            for (i, slot) in out.iter_mut().enumerate() {
                *slot = index.get(&format!("{base}_{i}")).copied();
            }
            out
        };
        Self {
            actual_q: six("actual_q"),
            actual_qd: six("actual_qd"),
            target_q: six("target_q"),
            target_qd: six("target_qd"),
            tcp_pose: six("actual_TCP_pose"),
            tcp_speed: six("actual_TCP_speed"),
            speed_scaling: one("speed_scaling"),
            target_speed_fraction: one("target_speed_fraction"),
            robot_mode: one("robot_mode"),
            // Older record.py recipes hold `safety_status` (same enumeration) instead.
            safety_mode: one("safety_mode").or_else(|| one("safety_status")),
            runtime_state: one("runtime_state"),
            robot_status_bits: one("robot_status_bits"),
            safety_status_bits: one("safety_status_bits"),
        }
    }
}

/// The fields of [`RobotState`] under their RTDE names, in the order [`state_to_row`] writes them.
pub const STATE_FIELD_NAMES: [&str; 44] = [
    "timestamp",
    "target_q_0",
    "target_q_1",
    "target_q_2",
    "target_q_3",
    "target_q_4",
    "target_q_5",
    "target_qd_0",
    "target_qd_1",
    "target_qd_2",
    "target_qd_3",
    "target_qd_4",
    "target_qd_5",
    "actual_q_0",
    "actual_q_1",
    "actual_q_2",
    "actual_q_3",
    "actual_q_4",
    "actual_q_5",
    "actual_qd_0",
    "actual_qd_1",
    "actual_qd_2",
    "actual_qd_3",
    "actual_qd_4",
    "actual_qd_5",
    "actual_TCP_pose_0",
    "actual_TCP_pose_1",
    "actual_TCP_pose_2",
    "actual_TCP_pose_3",
    "actual_TCP_pose_4",
    "actual_TCP_pose_5",
    "actual_TCP_speed_0",
    "actual_TCP_speed_1",
    "actual_TCP_speed_2",
    "actual_TCP_speed_3",
    "actual_TCP_speed_4",
    "actual_TCP_speed_5",
    "robot_mode",
    "safety_mode",
    "speed_scaling",
    "target_speed_fraction",
    "runtime_state",
    "robot_status_bits",
    "safety_status_bits",
];

/// Write `state` into `row` in the order of [`STATE_FIELD_NAMES`] (no allocation).
pub fn state_to_row(state: &RobotState, row: &mut [f64; 44]) {
    let mut values = [0.0; 44];
    let mut i = 0;
    let mut push = |v: f64| {
        if let Some(slot) = values.get_mut(i) {
            *slot = v;
        }
        i += 1;
    };
    push(state.timestamp_s);
    for block in [
        &state.target_q,
        &state.target_qd,
        &state.actual_q,
        &state.actual_qd,
        &state.actual_tcp_pose,
        &state.actual_tcp_speed,
    ] {
        for &v in block {
            push(v);
        }
    }
    push(f64::from(state.robot_mode));
    push(f64::from(state.safety_mode));
    push(state.speed_scaling);
    push(state.target_speed_fraction);
    push(f64::from(state.runtime_state));
    push(f64::from(state.robot_status_bits));
    push(f64::from(state.safety_status_bits));
    *row = values;
}

/// A recorded RTDE trace held in memory: timestamps and named numeric fields, one row per
/// controller sample, plus any verbatim leading columns.
///
/// Field 0 is always `timestamp` \[s\] (controller time); timestamps strictly increase.
#[derive(Debug, Clone)]
pub struct Trace {
    source: PathBuf,
    leading_names: Vec<String>,
    /// Row-major, `rows × leading_names.len()`.
    leading: Vec<String>,
    field_names: Vec<String>,
    index: HashMap<String, usize>,
    /// Row-major, `rows × field_names.len()`.
    values: Vec<f64>,
    duplicates_removed: usize,
    dialect: Dialect,
    state_columns: StateColumns,
}

impl Trace {
    /// An empty trace with the given RTDE field names, to be filled with [`Trace::push_row`].
    /// The first name must be `timestamp`; names must be distinct and non-empty.
    pub fn new<I, S>(field_names: I) -> Result<Trace>
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        let field_names: Vec<String> = field_names.into_iter().map(Into::into).collect();
        if field_names.first().map(String::as_str) != Some("timestamp") {
            return Err(RobotIoError::TraceUnknownField {
                field: "timestamp".to_owned(),
            });
        }
        let mut index = HashMap::with_capacity(field_names.len());
        for (i, name) in field_names.iter().enumerate() {
            if index.insert(name.clone(), i).is_some() {
                return Err(RobotIoError::TraceDuplicateField {
                    field: name.clone(),
                });
            }
        }
        let state_columns = StateColumns::new(&index);
        Ok(Trace {
            source: PathBuf::new(),
            leading_names: Vec::new(),
            leading: Vec::new(),
            field_names,
            index,
            values: Vec::new(),
            duplicates_removed: 0,
            dialect: Dialect::Comma,
            state_columns,
        })
    }

    /// Read a trace file, autodetecting its dialect (see the module docs).
    ///
    /// # Errors
    /// [`RobotIoError::Io`] if the file cannot be read; [`RobotIoError::TraceParse`] naming the
    /// file, line and column of the first malformed value.
    pub fn read(path: impl AsRef<Path>) -> Result<Trace> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|source| RobotIoError::Io {
            context: format!("reading trace {}", path.display()),
            source,
        })?;
        let text = match std::str::from_utf8(&bytes) {
            Ok(text) => text,
            Err(e) => {
                let valid = bytes.get(..e.valid_up_to()).unwrap_or_default();
                let line = 1 + count_line_ends(valid);
                return Err(RobotIoError::TraceParse {
                    file: path.to_path_buf(),
                    line,
                    column: 1,
                    kind: TraceParseErrorKind::NotUtf8,
                });
            }
        };
        Trace::parse(text, path)
    }

    /// Parse trace text; `source` names it in errors (usually the file path).
    pub fn parse(text: &str, source: impl AsRef<Path>) -> Result<Trace> {
        Parser::new(source.as_ref()).parse(text)
    }

    /// The file (or source name) the trace was read from; empty for built traces.
    pub fn source(&self) -> &Path {
        &self.source
    }

    /// The dialect the file was read in ([`Dialect::Comma`] for built traces).
    pub fn dialect(&self) -> Dialect {
        self.dialect
    }

    /// The RTDE field names, `timestamp` first, as in the file's header.
    pub fn field_names(&self) -> &[String] {
        &self.field_names
    }

    /// Number of RTDE fields (columns from `timestamp` on).
    pub fn field_count(&self) -> usize {
        self.field_names.len()
    }

    /// The names of the verbatim columns before `timestamp` (e.g. `time`, `_id`).
    pub fn leading_names(&self) -> &[String] {
        &self.leading_names
    }

    /// The text of leading column `name` at `row`.
    pub fn leading_value(&self, row: usize, name: &str) -> Option<&str> {
        let col = self.leading_names.iter().position(|n| n == name)?;
        let i = row
            .checked_mul(self.leading_names.len())?
            .checked_add(col)?;
        self.leading.get(i).map(String::as_str)
    }

    /// Rows (controller samples) after de-duplication.
    pub fn len(&self) -> usize {
        self.values
            .len()
            .checked_div(self.field_names.len())
            .unwrap_or(0)
    }

    /// Whether the trace has no rows.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The column index of field `name` (0 is `timestamp`).
    pub fn column_index(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }

    /// Controller timestamp of `row` \[s\].
    pub fn timestamp(&self, row: usize) -> Option<f64> {
        self.value_at(row, 0)
    }

    /// The value of field `name` at `row` (units as recorded: \[rad\], [rad/s], \[m\], \[s\], …).
    pub fn value(&self, row: usize, name: &str) -> Option<f64> {
        self.value_at(row, self.column_index(name)?)
    }

    /// The value at `row` and column index `column`.
    pub fn value_at(&self, row: usize, column: usize) -> Option<f64> {
        self.values.get(self.offset(row, column)?).copied()
    }

    /// All values of `row`, in the order of [`Trace::field_names`].
    pub fn row(&self, row: usize) -> Option<&[f64]> {
        let n = self.field_names.len();
        let start = row.checked_mul(n)?;
        self.values.get(start..start.checked_add(n)?)
    }

    /// Index into `values` of `row` and `column`, if both are in range.
    fn offset(&self, row: usize, column: usize) -> Option<usize> {
        let n = self.field_names.len();
        if column >= n {
            return None;
        }
        let i = row.checked_mul(n)?.checked_add(column)?;
        (i < self.values.len()).then_some(i)
    }

    /// The row holding the sample in force at controller time `t_s` \[s\]: the last row whose
    /// timestamp is ≤ `t_s` (sample and hold). `None` before the first row.
    pub fn row_at_time(&self, t_s: f64) -> Option<usize> {
        let (mut lo, mut hi) = (0, self.len());
        // Invariant: rows < lo have timestamp <= t_s, rows >= hi have timestamp > t_s.
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            match self.timestamp(mid) {
                Some(ts) if ts <= t_s => lo = mid + 1,
                _ => hi = mid,
            }
        }
        lo.checked_sub(1)
    }

    /// Set field `name` at `row` to `value` (e.g. to inject a protective stop into a recording).
    /// The timestamp column cannot be changed this way.
    pub fn set_value(&mut self, row: usize, name: &str, value: f64) -> Result<()> {
        let column = self.column_index(name).filter(|&c| c != 0).ok_or_else(|| {
            RobotIoError::TraceUnknownField {
                field: name.to_owned(),
            }
        })?;
        let rows = self.len();
        let slot = self
            .offset(row, column)
            .and_then(|i| self.values.get_mut(i))
            .ok_or(RobotIoError::TraceRowOutOfRange { row, rows })?;
        *slot = value;
        Ok(())
    }

    /// Append a row (values in the order of [`Trace::field_names`]); its timestamp must be finite
    /// and greater than the last row's. Traces with leading columns get empty leading values.
    pub fn push_row(&mut self, values: &[f64]) -> Result<()> {
        if values.len() != self.field_names.len() {
            return Err(RobotIoError::TraceRowLength {
                expected: self.field_names.len(),
                found: values.len(),
            });
        }
        let found = values.first().copied().unwrap_or(f64::NAN);
        let previous = self.len().checked_sub(1).and_then(|r| self.timestamp(r));
        let ordered = found.is_finite() && previous.is_none_or(|p| found > p);
        if !ordered {
            return Err(RobotIoError::TraceTimestampOrder {
                previous: previous.unwrap_or(f64::NEG_INFINITY),
                found,
            });
        }
        self.values.extend_from_slice(values);
        self.leading
            .extend(std::iter::repeat_n(String::new(), self.leading_names.len()));
        Ok(())
    }

    /// Copy the fields of `row` that the trace holds into `state` (RTDE names: `actual_q_i`,
    /// `actual_qd_i`, `target_q_i`, `target_qd_i`, `actual_TCP_pose_i`, `actual_TCP_speed_i`,
    /// `speed_scaling`, `target_speed_fraction`, `robot_mode`, `safety_mode` (or
    /// `safety_status`), `runtime_state`, `robot_status_bits`, `safety_status_bits`).
    /// Fields the trace lacks are left untouched. Allocates nothing.
    pub fn fill_state(&self, row: usize, state: &mut RobotState) -> Result<()> {
        let values = self.row(row).ok_or(RobotIoError::TraceRowOutOfRange {
            row,
            rows: self.len(),
        })?;
        let get = |c: Option<usize>| c.and_then(|c| values.get(c).copied());
        let fill6 = |cols: &[Option<usize>; 6], out: &mut [f64; 6]| {
            for (slot, &c) in out.iter_mut().zip(cols) {
                if let Some(v) = get(c) {
                    *slot = v;
                }
            }
        };
        let c = &self.state_columns;
        if let Some(t) = values.first() {
            state.timestamp_s = *t;
        }
        fill6(&c.actual_q, &mut state.actual_q);
        fill6(&c.actual_qd, &mut state.actual_qd);
        fill6(&c.target_q, &mut state.target_q);
        fill6(&c.target_qd, &mut state.target_qd);
        fill6(&c.tcp_pose, &mut state.actual_tcp_pose);
        fill6(&c.tcp_speed, &mut state.actual_tcp_speed);
        if let Some(v) = get(c.speed_scaling) {
            state.speed_scaling = v;
        }
        if let Some(v) = get(c.target_speed_fraction) {
            state.target_speed_fraction = v;
        }
        // Integer fields were read exactly; `as` saturates anything out of range.
        if let Some(v) = get(c.robot_mode) {
            state.robot_mode = v as i32;
        }
        if let Some(v) = get(c.safety_mode) {
            state.safety_mode = v as i32;
        }
        if let Some(v) = get(c.runtime_state) {
            state.runtime_state = v as u32;
        }
        if let Some(v) = get(c.robot_status_bits) {
            state.robot_status_bits = v as u32;
        }
        if let Some(v) = get(c.safety_status_bits) {
            state.safety_status_bits = v as u32;
        }
        Ok(())
    }

    /// Duplicates dropped on reading, the nominal period and the gaps (see the module docs).
    pub fn report(&self) -> TraceReport {
        let rows = self.len();
        let mut steps: Vec<f64> = (1..rows)
            .filter_map(|r| Some(self.timestamp(r)? - self.timestamp(r - 1)?))
            .filter(|d| *d > 0.0)
            .collect();
        steps.sort_by(f64::total_cmp);
        // Lower median: robust to the (longer) gap steps.
        let nominal = steps.get(steps.len().saturating_sub(1) / 2).copied();
        let mut gaps = Vec::new();
        if let Some(period) = nominal {
            for r in 1..rows {
                let (Some(t0), Some(t1)) = (self.timestamp(r - 1), self.timestamp(r)) else {
                    continue;
                };
                let step = t1 - t0;
                if step > 1.5 * period {
                    let periods = (step / period).round();
                    // `as` saturates; at least one period is missing past 1.5 periods.
                    let missing = (periods as u64).saturating_sub(1).max(1);
                    gaps.push(Gap {
                        after_row: r - 1,
                        after_timestamp: t0,
                        duration_s: step,
                        missing_periods: missing,
                    });
                }
            }
        }
        TraceReport {
            rows,
            duplicates_removed: self.duplicates_removed,
            nominal_period_s: nominal,
            gaps,
        }
    }

    /// Write the RTDE fields (from `timestamp` on; leading columns are not written) to a file.
    pub fn write(&self, path: impl AsRef<Path>, options: &WriteOptions) -> Result<()> {
        let path = path.as_ref();
        let file = std::fs::File::create(path).map_err(|source| RobotIoError::Io {
            context: format!("creating trace {}", path.display()),
            source,
        })?;
        let mut writer =
            TraceWriter::new(std::io::BufWriter::new(file), &self.field_names, options)?;
        for r in 0..self.len() {
            if let Some(row) = self.row(r) {
                writer.write_row(row)?;
            }
        }
        writer.flush()
    }

    /// Write the RTDE fields to `out` (see [`Trace::write`]).
    pub fn write_to<W: Write>(&self, out: W, options: &WriteOptions) -> Result<()> {
        let mut writer = TraceWriter::new(out, &self.field_names, options)?;
        for r in 0..self.len() {
            if let Some(row) = self.row(r) {
                writer.write_row(row)?;
            }
        }
        writer.flush()
    }
}

/// A streaming trace writer: a header, then one line per [`TraceWriter::write_row`]. Wrap the
/// output in a `BufWriter` and call [`TraceWriter::flush`] periodically so that a killed
/// recording keeps everything up to the last flush. Writing a row allocates nothing.
#[derive(Debug)]
pub struct TraceWriter<W: Write> {
    out: W,
    fields: usize,
    options: WriteOptions,
    rows: u64,
}

impl<W: Write> TraceWriter<W> {
    /// Start a trace on `out` with these field names (`timestamp` should come first, as both
    /// clients write it) and write the header line.
    pub fn new<S: AsRef<str>>(
        mut out: W,
        field_names: &[S],
        options: &WriteOptions,
    ) -> Result<Self> {
        let sep = options.dialect.separator();
        for (i, name) in field_names.iter().enumerate() {
            let name = name.as_ref();
            let res = if i == 0 {
                out.write_all(name.as_bytes())
            } else {
                write!(out, "{sep}{name}")
            };
            res.map_err(write_error)?;
        }
        out.write_all(b"\n").map_err(write_error)?;
        Ok(Self {
            out,
            fields: field_names.len(),
            options: *options,
            rows: 0,
        })
    }

    /// Write one row; `values` must have one value per field.
    pub fn write_row(&mut self, values: &[f64]) -> Result<()> {
        if values.len() != self.fields {
            return Err(RobotIoError::TraceRowLength {
                expected: self.fields,
                found: values.len(),
            });
        }
        let sep = self.options.dialect.separator();
        for (i, &v) in values.iter().enumerate() {
            if i > 0 {
                self.out.write_all(sep.as_bytes()).map_err(write_error)?;
            }
            write!(self.out, "{}", FormattedValue(v, self.options.float_format))
                .map_err(write_error)?;
        }
        self.out.write_all(b"\n").map_err(write_error)?;
        self.rows += 1;
        Ok(())
    }

    /// Rows written so far.
    pub fn rows_written(&self) -> u64 {
        self.rows
    }

    /// Flush the underlying writer.
    pub fn flush(&mut self) -> Result<()> {
        self.out.flush().map_err(write_error)
    }

    /// The underlying writer (not flushed).
    pub fn into_inner(self) -> W {
        self.out
    }
}

fn write_error(source: std::io::Error) -> RobotIoError {
    RobotIoError::Io {
        context: "writing trace".to_owned(),
        source,
    }
}

/// Formats one value per [`FloatFormat`] without allocating.
struct FormattedValue(f64, FloatFormat);

impl fmt::Display for FormattedValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = self.0;
        match self.1 {
            FloatFormat::Fixed(decimals) => write!(f, "{v:.*}", usize::from(decimals)),
            FloatFormat::RoundTrip => {
                let integral = v.fract() == 0.0
                    && v.abs() < 9_007_199_254_740_992.0
                    && !(v == 0.0 && v.is_sign_negative());
                if integral {
                    // Exact: |v| < 2^53 and integral.
                    write!(f, "{}", v as i64)
                } else {
                    // Rust's `Debug` for f64 is the shortest text that parses back identically.
                    write!(f, "{v:?}")
                }
            }
        }
    }
}

/// Counts line terminators (LF, CRLF, lone CR) in `bytes`.
fn count_line_ends(bytes: &[u8]) -> usize {
    let mut n = 0;
    let mut prev_cr = false;
    for &b in bytes {
        match b {
            b'\r' => n += 1,
            b'\n' if !prev_cr => n += 1,
            _ => {}
        }
        prev_cr = b == b'\r';
    }
    n
}

/// Iterates `(1-based line number, line)` over text ending lines in LF, CRLF or a lone CR.
struct Lines<'a> {
    rest: &'a str,
    line: usize,
}

impl<'a> Iterator for Lines<'a> {
    type Item = (usize, &'a str);

    fn next(&mut self) -> Option<Self::Item> {
        if self.rest.is_empty() {
            return None;
        }
        self.line += 1;
        let end = self.rest.find(['\r', '\n']).unwrap_or(self.rest.len());
        let (line, tail) = self.rest.split_at(end);
        let tail = tail
            .strip_prefix("\r\n")
            .or_else(|| tail.strip_prefix('\r'))
            .or_else(|| tail.strip_prefix('\n'))
            .unwrap_or(tail);
        self.rest = tail;
        Some((self.line, line))
    }
}

struct Parser<'p> {
    file: &'p Path,
}

impl<'p> Parser<'p> {
    fn new(file: &'p Path) -> Self {
        Self { file }
    }

    fn err(&self, line: usize, column: usize, kind: TraceParseErrorKind) -> RobotIoError {
        RobotIoError::TraceParse {
            file: self.file.to_path_buf(),
            line,
            column,
            kind,
        }
    }

    fn parse(&self, text: &str) -> Result<Trace> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lines = Lines {
            rest: text,
            line: 0,
        }
        .filter(|(_, l)| !l.trim().is_empty());
        let Some((header_line, header)) = lines.next() else {
            return Err(self.err(1, 1, TraceParseErrorKind::Empty));
        };
        let dialect = if header.contains(',') {
            Dialect::Comma
        } else {
            Dialect::Space
        };
        let names: Vec<&str> = split(header, dialect).collect();
        for (i, name) in names.iter().enumerate() {
            if name.is_empty() {
                return Err(self.err(header_line, i + 1, TraceParseErrorKind::EmptyColumnName));
            }
            if names.get(..i).is_some_and(|before| before.contains(name)) {
                return Err(self.err(
                    header_line,
                    i + 1,
                    TraceParseErrorKind::DuplicateColumn {
                        name: (*name).to_owned(),
                    },
                ));
            }
        }
        let Some(ts_col) = names.iter().position(|n| *n == "timestamp") else {
            return Err(self.err(header_line, 1, TraceParseErrorKind::MissingTimestamp));
        };
        let (leading_names, field_names) = names.split_at(ts_col);
        let mut trace = Trace::new(field_names.iter().copied())?;
        trace.source = self.file.to_path_buf();
        trace.dialect = dialect;
        trace.leading_names = leading_names.iter().map(|s| (*s).to_owned()).collect();
        let approx_rows = text.len() / (header.len().max(1)) + 1;
        trace.values.reserve(approx_rows * field_names.len());

        let columns = names.len();
        let mut row_buf: Vec<f64> = Vec::with_capacity(field_names.len());
        let mut lead_buf: Vec<&str> = Vec::with_capacity(ts_col);
        let mut last_ts: Option<f64> = None;
        for (line_no, line) in lines {
            row_buf.clear();
            lead_buf.clear();
            let mut found = 0;
            for (col, token) in split(line, dialect).enumerate() {
                found = col + 1;
                if col >= columns {
                    continue; // counted, reported below
                }
                if col < ts_col {
                    lead_buf.push(token);
                    continue;
                }
                let field = names.get(col).copied().unwrap_or_default();
                let value = self.parse_value(token, field, line_no, col + 1)?;
                if col == ts_col && !value.is_finite() {
                    return Err(self.err(
                        line_no,
                        col + 1,
                        TraceParseErrorKind::TimestampNotFinite {
                            text: token.to_owned(),
                        },
                    ));
                }
                row_buf.push(value);
            }
            if found != columns {
                return Err(self.err(
                    line_no,
                    found.min(columns) + 1,
                    TraceParseErrorKind::ColumnCount {
                        expected: columns,
                        found,
                    },
                ));
            }
            let ts = row_buf.first().copied().unwrap_or(f64::NAN);
            match last_ts {
                Some(prev) if ts == prev => {
                    trace.duplicates_removed += 1;
                    continue;
                }
                Some(prev) if ts < prev => {
                    return Err(self.err(
                        line_no,
                        ts_col + 1,
                        TraceParseErrorKind::TimestampDecreasing {
                            previous: prev,
                            found: ts,
                        },
                    ));
                }
                _ => {}
            }
            last_ts = Some(ts);
            trace.values.extend_from_slice(&row_buf);
            trace
                .leading
                .extend(lead_buf.iter().map(|s| (*s).to_owned()));
        }
        trace.values.shrink_to_fit();
        Ok(trace)
    }

    fn parse_value(&self, token: &str, field: &str, line: usize, column: usize) -> Result<f64> {
        let digits = token.strip_prefix(['-', '+']).unwrap_or(token);
        if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) {
            let magnitude = digits.parse::<u128>().unwrap_or(u128::MAX);
            if magnitude > MAX_EXACT_INTEGER {
                return Err(self.err(
                    line,
                    column,
                    TraceParseErrorKind::IntegerTooLarge {
                        field: field.to_owned(),
                        text: token.to_owned(),
                    },
                ));
            }
        }
        token.parse::<f64>().map_err(|_| {
            self.err(
                line,
                column,
                TraceParseErrorKind::NotANumber {
                    field: field.to_owned(),
                    text: token.to_owned(),
                },
            )
        })
    }
}

fn split(line: &str, dialect: Dialect) -> Box<dyn Iterator<Item = &str> + '_> {
    match dialect {
        Dialect::Comma => Box::new(line.split(',').map(str::trim)),
        Dialect::Space => Box::new(line.split_ascii_whitespace()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::runtime_state;

    fn data(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../data/rtde-traces")
            .join(name)
    }

    /// Every recording in `data/rtde-traces`, with its rows and RTDE fields (counted
    /// independently from the files: lines with data, columns from `timestamp` on).
    const REAL_TRACES: [(&str, usize, usize, Dialect); 6] = [
        ("eseries_10hz_recordpy_paused.csv", 256, 119, Dialect::Space),
        ("ur3e_25hz_rad_segment_L0L1.csv", 29, 173, Dialect::Comma),
        ("ur3e_25hz_rad_segment_L1L2.csv", 65, 173, Dialect::Comma),
        ("ur3e_25hz_rad_segment_L2L3.csv", 40, 173, Dialect::Comma),
        ("ur3e_25hz_rad_segment_L3L4.csv", 49, 173, Dialect::Comma),
        ("ur3e_25hz_rad_segment_L4L5.csv", 42, 173, Dialect::Comma),
    ];

    fn parse_err(text: &str) -> (usize, usize, TraceParseErrorKind, String) {
        match Trace::parse(text, "bad.csv") {
            Err(e @ RobotIoError::TraceParse { .. }) => {
                let msg = e.to_string();
                let RobotIoError::TraceParse {
                    line, column, kind, ..
                } = e
                else {
                    unreachable!()
                };
                (line, column, kind, msg)
            }
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    #[test]
    fn every_real_trace_parses_with_expected_rows_and_fields() {
        for (name, rows, fields, dialect) in REAL_TRACES {
            let trace = Trace::read(data(name)).unwrap();
            assert_eq!(trace.len(), rows, "{name}");
            assert_eq!(trace.field_count(), fields, "{name}");
            assert_eq!(trace.dialect(), dialect, "{name}");
            assert_eq!(trace.field_names()[0], "timestamp");
            let report = trace.report();
            assert_eq!(report.duplicates_removed, 0, "{name}");
            assert!(report.gaps.is_empty(), "{name}: {:?}", report.gaps);
            let expected_period = if name.contains("10hz") { 0.1 } else { 0.04 };
            let period = report.nominal_period_s.unwrap();
            assert!((period - expected_period).abs() < 1e-6, "{name}: {period}");
        }
    }

    #[test]
    fn record_py_values_are_read_exactly() {
        // Values copied from the first data line of the file.
        let trace = Trace::read(data("eseries_10hz_recordpy_paused.csv")).unwrap();
        assert_eq!(trace.timestamp(0), Some(4029.5389999999998));
        assert_eq!(trace.value(0, "actual_q_0"), Some(1.2144851098128129e-05));
        assert_eq!(trace.value(0, "actual_q_1"), Some(-1.5707534360957034));
        assert_eq!(
            trace.value(0, "actual_TCP_pose_2"),
            Some(1.0802957867938283)
        );
        assert_eq!(trace.value(0, "no_such_field"), None);
        assert!(trace.leading_names().is_empty());
        // `-0.0` in the file keeps its sign.
        let qd_2 = trace.value(0, "actual_qd_2").unwrap();
        assert!(qd_2 == 0.0 && qd_2.is_sign_negative());

        let mut state = RobotState::default();
        trace.fill_state(0, &mut state).unwrap();
        assert_eq!(state.timestamp_s, 4029.5389999999998);
        assert_eq!(state.actual_q[1], -1.5707534360957034);
        assert_eq!(state.runtime_state, runtime_state::PAUSED);
        assert_eq!(state.robot_mode, 7);
        assert_eq!(state.safety_mode, 1, "from the `safety_status` column");
        assert_eq!(state.speed_scaling, 0.0);
        assert!(matches!(
            trace.fill_state(256, &mut state),
            Err(RobotIoError::TraceRowOutOfRange {
                row: 256,
                rows: 256
            })
        ));
    }

    #[test]
    fn rad_segments_keep_leading_columns_and_join_without_gaps() {
        let mut last: Option<f64> = None;
        for (name, ..) in REAL_TRACES.iter().skip(1) {
            let trace = Trace::read(data(name)).unwrap();
            assert_eq!(trace.leading_names(), ["time", "_id"]);
            assert_eq!(trace.leading_value(0, "time"), Some("1"));
            assert!(
                trace
                    .leading_value(0, "_id")
                    .unwrap()
                    .starts_with("2021:10:05:12:08:")
            );
            let first = trace.timestamp(0).unwrap();
            if let Some(prev) = last {
                assert!(
                    (first - prev - 0.04).abs() < 1e-6,
                    "{name}: {prev} -> {first}"
                );
            }
            last = trace.timestamp(trace.len() - 1);
            // The controller reports speed_scaling 0 exactly when the program is not playing.
            for r in 0..trace.len() {
                let rs = trace.value(r, "runtime_state").unwrap();
                let ss = trace.value(r, "speed_scaling").unwrap();
                assert_eq!(ss == 0.0, rs != 2.0, "{name} row {r}");
            }
        }
    }

    #[test]
    fn duplicates_are_dropped_and_gaps_reported() {
        // Simulated 500 Hz recording: rows 2 and 5 repeat a timestamp, 3 cycles are missing
        // after 0.006 s, 1 after 0.014 s.
        let text = "timestamp,actual_q_0\n\
                    0.000,0\n0.002,1\n0.002,1\n0.004,2\n0.006,3\n0.006,3\n\
                    0.014,4\n0.016,5\n0.020,6\n0.022,7\n";
        let trace = Trace::parse(text, "sim.csv").unwrap();
        assert_eq!(trace.len(), 8);
        let q: Vec<f64> = (0..8)
            .map(|r| trace.value(r, "actual_q_0").unwrap())
            .collect();
        assert_eq!(q, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
        let report = trace.report();
        assert_eq!(report.rows, 8);
        assert_eq!(report.duplicates_removed, 2);
        assert!((report.nominal_period_s.unwrap() - 0.002).abs() < 1e-12);
        assert_eq!(report.gaps.len(), 2);
        assert_eq!(report.gaps[0].after_row, 3);
        assert_eq!(report.gaps[0].after_timestamp, 0.006);
        assert_eq!(report.gaps[0].missing_periods, 3);
        assert_eq!(report.gaps[1].after_timestamp, 0.016);
        assert_eq!(report.gaps[1].missing_periods, 1);
        assert_eq!(report.missing_periods(), 4);
    }

    #[test]
    fn line_endings_blank_lines_bom_and_whitespace_runs() {
        let lf = "timestamp a\n0.1 1\n0.2 2\n";
        let crlf = "\u{feff}timestamp a\r\n0.1 1\r\n\r\n0.2 2\r\n";
        let cr = "timestamp  a\r0.1\t1\r0.2   2";
        for text in [lf, crlf, cr] {
            let trace = Trace::parse(text, "t").unwrap();
            assert_eq!(trace.len(), 2, "{text:?}");
            assert_eq!(trace.value(1, "a"), Some(2.0));
        }
        // Line numbers count CR-only line ends.
        let (line, column, ..) = parse_err("timestamp,a\r0.1,1\r0.2,x\r");
        assert_eq!((line, column), (3, 2));
    }

    #[test]
    fn malformed_input_names_file_line_and_column() {
        let (line, column, kind, msg) = parse_err("timestamp,a,b\n0.0,1,2\n0.1,1,oops\n");
        assert_eq!((line, column), (3, 3));
        assert_eq!(
            kind,
            TraceParseErrorKind::NotANumber {
                field: "b".into(),
                text: "oops".into()
            }
        );
        assert_eq!(msg, "bad.csv:3:3: field `b`: `oops` is not a number");

        let (line, column, kind, _) = parse_err("timestamp,a,b\n0.0,1\n");
        assert_eq!((line, column), (2, 3));
        assert_eq!(
            kind,
            TraceParseErrorKind::ColumnCount {
                expected: 3,
                found: 2
            }
        );
        let (line, column, ..) = parse_err("timestamp,a\n0.0,1,5\n");
        assert_eq!((line, column), (2, 3));

        let (line, column, kind, _) = parse_err("time,a\n0,1\n");
        assert_eq!(
            (line, column, kind),
            (1, 1, TraceParseErrorKind::MissingTimestamp)
        );

        let (line, column, kind, _) = parse_err("timestamp,a,a\n");
        assert_eq!((line, column), (1, 3));
        assert_eq!(
            kind,
            TraceParseErrorKind::DuplicateColumn { name: "a".into() }
        );

        let (line, column, kind, _) = parse_err("x,timestamp,a\nid,0.2,1\nid,0.1,1\n");
        assert_eq!((line, column), (3, 2));
        assert_eq!(
            kind,
            TraceParseErrorKind::TimestampDecreasing {
                previous: 0.2,
                found: 0.1
            }
        );

        let (line, column, kind, _) = parse_err("timestamp,a\nnan,1\n");
        assert_eq!((line, column), (2, 1));
        assert!(matches!(
            kind,
            TraceParseErrorKind::TimestampNotFinite { .. }
        ));

        // 2^53 is exact; 2^53 + 1 is not.
        let ok = Trace::parse("timestamp,bits\n0,9007199254740992\n", "t").unwrap();
        assert_eq!(ok.value(0, "bits"), Some(9_007_199_254_740_992.0));
        let (line, column, kind, _) = parse_err("timestamp,bits\n0,9007199254740993\n");
        assert_eq!((line, column), (2, 2));
        assert!(matches!(kind, TraceParseErrorKind::IntegerTooLarge { .. }));
        let (.., kind, _) =
            parse_err("timestamp,bits\n0,-18446744073709551615000000000000000000000\n");
        assert!(matches!(kind, TraceParseErrorKind::IntegerTooLarge { .. }));

        let (line, column, kind, _) = parse_err("\n\n");
        assert_eq!((line, column, kind), (1, 1, TraceParseErrorKind::Empty));
    }

    #[test]
    fn read_names_the_file_and_reports_io_and_utf8_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("broken.csv");
        std::fs::write(&path, b"timestamp,a\n0,1\n0.1,\xff\n").unwrap();
        let err = Trace::read(&path).unwrap_err();
        let RobotIoError::TraceParse {
            file, line, kind, ..
        } = &err
        else {
            panic!("{err:?}")
        };
        assert_eq!(file, &path);
        assert_eq!(*line, 3);
        assert_eq!(kind, &TraceParseErrorKind::NotUtf8);
        assert!(err.to_string().contains("broken.csv:3:"));

        let missing = Trace::read(dir.path().join("missing.csv")).unwrap_err();
        assert!(matches!(missing, RobotIoError::Io { .. }));
        assert!(missing.to_string().contains("missing.csv"));
    }

    fn assert_bit_identical(a: &Trace, b: &Trace) {
        assert_eq!(a.field_names(), b.field_names());
        assert_eq!(a.len(), b.len());
        for r in 0..a.len() {
            for (x, y) in a.row(r).unwrap().iter().zip(b.row(r).unwrap()) {
                assert_eq!(x.to_bits(), y.to_bits(), "row {r}: {x:?} vs {y:?}");
            }
        }
    }

    #[test]
    fn real_traces_round_trip_bit_exact_in_both_dialects() {
        let dir = tempfile::tempdir().unwrap();
        for (name, ..) in REAL_TRACES {
            let trace = Trace::read(data(name)).unwrap();
            for (options, dialect) in [
                (WriteOptions::ur_rtde(), Dialect::Comma),
                (WriteOptions::record_py(), Dialect::Space),
            ] {
                let path = dir.path().join(format!("{name}.{dialect:?}.csv"));
                trace.write(&path, &options).unwrap();
                let back = Trace::read(&path).unwrap();
                assert_eq!(back.dialect(), dialect);
                assert_bit_identical(&trace, &back);
            }
        }
    }

    #[test]
    fn awkward_values_round_trip_bit_exact() {
        let specials = [
            -0.0,
            0.0,
            0.1 + 0.2,
            f64::MIN_POSITIVE,
            5e-324,
            1e-300,
            f64::MAX,
            -f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
            9_007_199_254_740_992.0,
            -9_007_199_254_740_991.0,
            1e22,
            std::f64::consts::PI,
            4029.5389999999998,
            7.0,
        ];
        let mut trace = Trace::new(["timestamp", "v"]).unwrap();
        for (i, v) in specials.iter().enumerate() {
            trace.push_row(&[i as f64 * 0.002, *v]).unwrap();
        }
        trace.push_row(&[1.0, f64::NAN]).unwrap();
        for options in [WriteOptions::ur_rtde(), WriteOptions::record_py()] {
            let mut buf = Vec::new();
            trace.write_to(&mut buf, &options).unwrap();
            let back = Trace::parse(std::str::from_utf8(&buf).unwrap(), "mem").unwrap();
            assert_bit_identical(&trace, &back);
        }
    }

    #[test]
    fn writers_produce_the_two_dialects() {
        let mut trace = Trace::new(["timestamp", "actual_q_0", "runtime_state"]).unwrap();
        trace.push_row(&[0.002, -1.5, 2.0]).unwrap();
        trace.push_row(&[0.004, 0.25, 4.0]).unwrap();
        let mut comma = Vec::new();
        trace
            .write_to(&mut comma, &WriteOptions::ur_rtde())
            .unwrap();
        assert_eq!(
            String::from_utf8(comma).unwrap(),
            "timestamp,actual_q_0,runtime_state\n0.002,-1.5,2\n0.004,0.25,4\n"
        );
        let mut space = Vec::new();
        trace
            .write_to(&mut space, &WriteOptions::record_py())
            .unwrap();
        assert_eq!(
            String::from_utf8(space).unwrap(),
            "timestamp actual_q_0 runtime_state\n0.002 -1.5 2\n0.004 0.25 4\n"
        );
        let mut fixed = Vec::new();
        let options = WriteOptions {
            dialect: Dialect::Comma,
            float_format: FloatFormat::Fixed(6),
        };
        trace.write_to(&mut fixed, &options).unwrap();
        assert_eq!(
            String::from_utf8(fixed).unwrap(),
            "timestamp,actual_q_0,runtime_state\n\
             0.002000,-1.500000,2.000000\n0.004000,0.250000,4.000000\n"
        );
    }

    #[test]
    fn streaming_writer_checks_row_length_and_counts_rows() {
        let mut writer =
            TraceWriter::new(Vec::new(), &["timestamp", "a"], &WriteOptions::ur_rtde()).unwrap();
        writer.write_row(&[0.0, 1.0]).unwrap();
        assert!(matches!(
            writer.write_row(&[0.0]),
            Err(RobotIoError::TraceRowLength {
                expected: 2,
                found: 1
            })
        ));
        writer.flush().unwrap();
        assert_eq!(writer.rows_written(), 1);
        assert_eq!(writer.into_inner(), b"timestamp,a\n0,1\n");
    }

    #[test]
    fn state_rows_round_trip_through_a_file() {
        let state = RobotState {
            timestamp_s: 12.346,
            actual_q: [0.1, -1.2, 1.3, -0.4, 0.5, -0.6],
            actual_qd: [0.01, 0.02, -0.03, 0.0, -0.0, 0.06],
            target_q: [0.11, -1.21, 1.31, -0.41, 0.51, -0.61],
            target_qd: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            actual_tcp_pose: [-0.1, -0.2, 0.3, 3.1, 0.2, -0.1],
            actual_tcp_speed: [0.001, 0.0, 0.0, 0.0, 0.0, 0.5],
            speed_scaling: 0.75,
            target_speed_fraction: 0.5,
            robot_mode: 7,
            safety_mode: 3,
            runtime_state: 4,
            robot_status_bits: 3,
            safety_status_bits: 1 << 2 | 1 << 10,
        };
        let mut row = [0.0; 44];
        state_to_row(&state, &mut row);
        let mut trace = Trace::new(STATE_FIELD_NAMES).unwrap();
        trace.push_row(&row).unwrap();
        let mut buf = Vec::new();
        trace.write_to(&mut buf, &WriteOptions::ur_rtde()).unwrap();
        let back = Trace::parse(std::str::from_utf8(&buf).unwrap(), "mem").unwrap();
        let mut out = RobotState::default();
        back.fill_state(0, &mut out).unwrap();
        assert_eq!(out, state);
        assert!(out.actual_qd[4].is_sign_negative());
    }

    #[test]
    fn building_editing_and_seeking() {
        assert!(matches!(
            Trace::new(["a", "timestamp"]),
            Err(RobotIoError::TraceUnknownField { .. })
        ));
        assert!(matches!(
            Trace::new(["timestamp", "a", "a"]),
            Err(RobotIoError::TraceDuplicateField { .. })
        ));
        let mut trace = Trace::new(["timestamp", "safety_mode"]).unwrap();
        assert!(trace.is_empty());
        assert_eq!(trace.report().nominal_period_s, None);
        trace.push_row(&[1.0, 1.0]).unwrap();
        trace.push_row(&[1.002, 1.0]).unwrap();
        assert!(matches!(
            trace.push_row(&[1.002, 1.0]),
            Err(RobotIoError::TraceTimestampOrder { .. })
        ));
        assert!(matches!(
            trace.push_row(&[1.004]),
            Err(RobotIoError::TraceRowLength { .. })
        ));
        trace.set_value(1, "safety_mode", 3.0).unwrap();
        assert_eq!(trace.value(1, "safety_mode"), Some(3.0));
        assert!(trace.set_value(1, "timestamp", 0.0).is_err());
        assert!(matches!(
            trace.set_value(2, "safety_mode", 3.0),
            Err(RobotIoError::TraceRowOutOfRange { row: 2, rows: 2 })
        ));
        assert_eq!(trace.row_at_time(0.5), None);
        assert_eq!(trace.row_at_time(1.0), Some(0));
        assert_eq!(trace.row_at_time(1.0019), Some(0));
        assert_eq!(trace.row_at_time(1.002), Some(1));
        assert_eq!(trace.row_at_time(99.0), Some(1));
        assert_eq!(trace.value_at(0, 2), None);
        assert_eq!(trace.row(2), None);
    }
}
