//! The RTDE wire format: package framing, every package type and every field type.
//!
//! Every package is `u16 size` (the whole package, header included), `u8 type`, then the
//! payload, all big-endian. The same type byte means a request from the client and a reply
//! from the controller, so decoding is directional: [`ClientPackage::decode`] reads what a
//! client sends, [`ControllerPackage::decode`] what a controller sends. Decoding borrows from
//! the input and never allocates; encoding appends to a caller-owned `Vec<u8>` that is reused.
//!
//! A [`Recipe`] is built once from the field names and their types and precomputes each
//! field's byte offset, so reading a field of a data package is a bounds-checked slice read.
//!
//! ```
//! use robot_io::codec::{ClientPackage, FieldType, Recipe, Value};
//! let mut out = Vec::new();
//! ClientPackage::RequestProtocolVersion { version: 2 }.encode(&mut out)?;
//! assert_eq!(out, [0x00, 0x05, 0x56, 0x00, 0x02]);
//!
//! let recipe = Recipe::new(1, &["input_int_register_24"], &[FieldType::Int32])?;
//! out.clear();
//! recipe.encode_values(&[Value::Int32(1)], &mut out)?;
//! assert_eq!(out, [0x00, 0x08, 0x55, 0x01, 0x00, 0x00, 0x00, 0x01]);
//! # Ok::<(), robot_io::RobotIoError>(())
//! ```

use crate::{Result, RobotIoError};

/// RTDE protocol version this crate speaks.
pub const PROTOCOL_VERSION: u16 = 2;
/// Size of the package header (`u16` size + `u8` type) \[B\].
pub const HEADER_LEN: usize = 3;
/// Largest package the `u16` size allows \[B\].
pub const MAX_PACKAGE_LEN: usize = u16::MAX as usize;
/// Longest comma-separated name list the controller accepts \[B\].
pub const MAX_NAME_LIST_LEN: usize = 2048;
/// Highest output frequency of an e-Series controller \[Hz\].
pub const MAX_FREQUENCY_HZ: f64 = 500.0;

/// The package type bytes.
pub mod kind {
    /// `V`: request protocol version.
    pub const REQUEST_PROTOCOL_VERSION: u8 = b'V';
    /// `v`: get controller (URControl) version.
    pub const GET_URCONTROL_VERSION: u8 = b'v';
    /// `M`: text message.
    pub const TEXT_MESSAGE: u8 = b'M';
    /// `U`: data package.
    pub const DATA_PACKAGE: u8 = b'U';
    /// `O`: set up outputs.
    pub const SETUP_OUTPUTS: u8 = b'O';
    /// `I`: set up inputs.
    pub const SETUP_INPUTS: u8 = b'I';
    /// `S`: start the output stream.
    pub const START: u8 = b'S';
    /// `P`: pause the output stream.
    pub const PAUSE: u8 = b'P';
}

/// An RTDE field type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FieldType {
    /// `DOUBLE`: f64.
    Double,
    /// `UINT8`: u8.
    Uint8,
    /// `UINT32`: u32.
    Uint32,
    /// `UINT64`: u64.
    Uint64,
    /// `INT32`: i32.
    Int32,
    /// `BOOL`: one byte, 0 or 1.
    Bool,
    /// `VECTOR3D`: 3×f64.
    Vector3d,
    /// `VECTOR6D`: 6×f64.
    Vector6d,
    /// `VECTOR6INT32`: 6×i32.
    Vector6Int32,
    /// `VECTOR6UINT32`: 6×u32.
    Vector6Uint32,
}

impl FieldType {
    /// Every field type.
    pub const ALL: [FieldType; 10] = [
        FieldType::Double,
        FieldType::Uint8,
        FieldType::Uint32,
        FieldType::Uint64,
        FieldType::Int32,
        FieldType::Bool,
        FieldType::Vector3d,
        FieldType::Vector6d,
        FieldType::Vector6Int32,
        FieldType::Vector6Uint32,
    ];

    /// Encoded size \[B\].
    pub const fn size(self) -> usize {
        match self {
            FieldType::Double | FieldType::Uint64 => 8,
            FieldType::Uint8 | FieldType::Bool => 1,
            FieldType::Uint32 | FieldType::Int32 => 4,
            FieldType::Vector3d => 24,
            FieldType::Vector6d => 48,
            FieldType::Vector6Int32 | FieldType::Vector6Uint32 => 24,
        }
    }

    /// Number of scalar components (1 for scalars, 3 or 6 for vectors).
    pub const fn width(self) -> usize {
        match self {
            FieldType::Vector3d => 3,
            FieldType::Vector6d | FieldType::Vector6Int32 | FieldType::Vector6Uint32 => 6,
            _ => 1,
        }
    }

    /// The type string on the wire.
    pub const fn as_str(self) -> &'static str {
        match self {
            FieldType::Double => "DOUBLE",
            FieldType::Uint8 => "UINT8",
            FieldType::Uint32 => "UINT32",
            FieldType::Uint64 => "UINT64",
            FieldType::Int32 => "INT32",
            FieldType::Bool => "BOOL",
            FieldType::Vector3d => "VECTOR3D",
            FieldType::Vector6d => "VECTOR6D",
            FieldType::Vector6Int32 => "VECTOR6INT32",
            FieldType::Vector6Uint32 => "VECTOR6UINT32",
        }
    }

    /// Parses a wire type string; `None` for anything else (including `NOT_FOUND`, `IN_USE`).
    pub fn parse(s: &str) -> Option<FieldType> {
        FieldType::ALL.into_iter().find(|t| t.as_str() == s)
    }
}

impl std::fmt::Display for FieldType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One field's value. `Copy`, so reading it allocates nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    /// `DOUBLE`.
    Double(f64),
    /// `UINT8`.
    Uint8(u8),
    /// `UINT32`.
    Uint32(u32),
    /// `UINT64`.
    Uint64(u64),
    /// `INT32`.
    Int32(i32),
    /// `BOOL`.
    Bool(bool),
    /// `VECTOR3D`.
    Vector3d([f64; 3]),
    /// `VECTOR6D`.
    Vector6d([f64; 6]),
    /// `VECTOR6INT32`.
    Vector6Int32([i32; 6]),
    /// `VECTOR6UINT32`.
    Vector6Uint32([u32; 6]),
}

/// Reads `N` bytes at `at` of `buf`, or a `Truncated` error.
fn take<const N: usize>(buf: &[u8], at: usize, what: &'static str) -> Result<[u8; N]> {
    let end = at.checked_add(N).ok_or(RobotIoError::Malformed {
        reason: "offset overflow",
    })?;
    buf.get(at..end)
        .and_then(|s| <[u8; N]>::try_from(s).ok())
        .ok_or(RobotIoError::Truncated {
            what,
            needed: end,
            available: buf.len(),
        })
}

impl Value {
    /// This value's field type.
    pub const fn field_type(&self) -> FieldType {
        match self {
            Value::Double(_) => FieldType::Double,
            Value::Uint8(_) => FieldType::Uint8,
            Value::Uint32(_) => FieldType::Uint32,
            Value::Uint64(_) => FieldType::Uint64,
            Value::Int32(_) => FieldType::Int32,
            Value::Bool(_) => FieldType::Bool,
            Value::Vector3d(_) => FieldType::Vector3d,
            Value::Vector6d(_) => FieldType::Vector6d,
            Value::Vector6Int32(_) => FieldType::Vector6Int32,
            Value::Vector6Uint32(_) => FieldType::Vector6Uint32,
        }
    }

    /// A zero value of type `ty`.
    pub const fn zero(ty: FieldType) -> Value {
        match ty {
            FieldType::Double => Value::Double(0.0),
            FieldType::Uint8 => Value::Uint8(0),
            FieldType::Uint32 => Value::Uint32(0),
            FieldType::Uint64 => Value::Uint64(0),
            FieldType::Int32 => Value::Int32(0),
            FieldType::Bool => Value::Bool(false),
            FieldType::Vector3d => Value::Vector3d([0.0; 3]),
            FieldType::Vector6d => Value::Vector6d([0.0; 6]),
            FieldType::Vector6Int32 => Value::Vector6Int32([0; 6]),
            FieldType::Vector6Uint32 => Value::Vector6Uint32([0; 6]),
        }
    }

    /// Decodes a value of type `ty` at byte `at` of `buf`.
    pub fn decode(ty: FieldType, buf: &[u8], at: usize) -> Result<Value> {
        const W: &str = "field";
        let f64_at = |i: usize| take::<8>(buf, at + 8 * i, W).map(f64::from_be_bytes);
        let i32_at = |i: usize| take::<4>(buf, at + 4 * i, W).map(i32::from_be_bytes);
        let u32_at = |i: usize| take::<4>(buf, at + 4 * i, W).map(u32::from_be_bytes);
        Ok(match ty {
            FieldType::Double => Value::Double(f64_at(0)?),
            FieldType::Uint8 => Value::Uint8(u8::from_be_bytes(take::<1>(buf, at, W)?)),
            FieldType::Uint32 => Value::Uint32(u32_at(0)?),
            FieldType::Uint64 => Value::Uint64(u64::from_be_bytes(take::<8>(buf, at, W)?)),
            FieldType::Int32 => Value::Int32(i32_at(0)?),
            FieldType::Bool => Value::Bool(u8::from_be_bytes(take::<1>(buf, at, W)?) != 0),
            FieldType::Vector3d => Value::Vector3d([f64_at(0)?, f64_at(1)?, f64_at(2)?]),
            FieldType::Vector6d => Value::Vector6d([
                f64_at(0)?,
                f64_at(1)?,
                f64_at(2)?,
                f64_at(3)?,
                f64_at(4)?,
                f64_at(5)?,
            ]),
            FieldType::Vector6Int32 => Value::Vector6Int32([
                i32_at(0)?,
                i32_at(1)?,
                i32_at(2)?,
                i32_at(3)?,
                i32_at(4)?,
                i32_at(5)?,
            ]),
            FieldType::Vector6Uint32 => Value::Vector6Uint32([
                u32_at(0)?,
                u32_at(1)?,
                u32_at(2)?,
                u32_at(3)?,
                u32_at(4)?,
                u32_at(5)?,
            ]),
        })
    }

    /// Appends the big-endian encoding to `out`.
    pub fn encode(&self, out: &mut Vec<u8>) {
        match *self {
            Value::Double(v) => out.extend_from_slice(&v.to_be_bytes()),
            Value::Uint8(v) => out.push(v),
            Value::Uint32(v) => out.extend_from_slice(&v.to_be_bytes()),
            Value::Uint64(v) => out.extend_from_slice(&v.to_be_bytes()),
            Value::Int32(v) => out.extend_from_slice(&v.to_be_bytes()),
            Value::Bool(v) => out.push(u8::from(v)),
            Value::Vector3d(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
            Value::Vector6d(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
            Value::Vector6Int32(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
            Value::Vector6Uint32(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
        }
    }

    /// Scalar component `i` as f64 (integers converted exactly up to 2^53; `None` past the
    /// width).
    pub fn component(&self, i: usize) -> Option<f64> {
        match self {
            Value::Double(v) => (i == 0).then_some(*v),
            Value::Uint8(v) => (i == 0).then_some(f64::from(*v)),
            Value::Uint32(v) => (i == 0).then_some(f64::from(*v)),
            Value::Uint64(v) => (i == 0).then_some(*v as f64),
            Value::Int32(v) => (i == 0).then_some(f64::from(*v)),
            Value::Bool(v) => (i == 0).then_some(if *v { 1.0 } else { 0.0 }),
            Value::Vector3d(v) => v.get(i).copied(),
            Value::Vector6d(v) => v.get(i).copied(),
            Value::Vector6Int32(v) => v.get(i).map(|x| f64::from(*x)),
            Value::Vector6Uint32(v) => v.get(i).map(|x| f64::from(*x)),
        }
    }

    /// Builds a value of type `ty` from f64 components (as read from a CSV trace): integers
    /// are truncated towards zero and saturate; missing components read as 0.
    pub fn from_components(ty: FieldType, c: &[f64]) -> Value {
        let g = |i: usize| c.get(i).copied().unwrap_or(0.0);
        let v6 = || [g(0), g(1), g(2), g(3), g(4), g(5)];
        match ty {
            FieldType::Double => Value::Double(g(0)),
            FieldType::Uint8 => Value::Uint8(g(0) as u8),
            FieldType::Uint32 => Value::Uint32(g(0) as u32),
            FieldType::Uint64 => Value::Uint64(g(0) as u64),
            FieldType::Int32 => Value::Int32(g(0) as i32),
            FieldType::Bool => Value::Bool(g(0) != 0.0),
            FieldType::Vector3d => Value::Vector3d([g(0), g(1), g(2)]),
            FieldType::Vector6d => Value::Vector6d(v6()),
            FieldType::Vector6Int32 => Value::Vector6Int32(v6().map(|x| x as i32)),
            FieldType::Vector6Uint32 => Value::Vector6Uint32(v6().map(|x| x as u32)),
        }
    }
}

/// The type of a known RTDE field (outputs and inputs of e-Series controllers, from UR's RTDE
/// guide), or `None` for names the controller would answer `NOT_FOUND` to.
pub fn known_field_type(name: &str) -> Option<FieldType> {
    use FieldType::*;
    let ty = match name {
        "timestamp"
        | "actual_execution_time"
        | "speed_scaling"
        | "target_speed_fraction"
        | "actual_momentum"
        | "actual_main_voltage"
        | "actual_robot_voltage"
        | "actual_robot_current"
        | "standard_analog_input0"
        | "standard_analog_input1"
        | "standard_analog_output0"
        | "standard_analog_output1"
        | "io_current"
        | "euromap67_24V_voltage"
        | "euromap67_24V_current"
        | "tool_analog_input0"
        | "tool_analog_input1"
        | "tool_output_current"
        | "tool_temperature"
        | "tcp_force_scalar"
        | "joint_position_deviation_ratio"
        | "payload"
        | "speed_slider_fraction"
        | "standard_analog_output_0"
        | "standard_analog_output_1"
        | "collision_detection_ratio" => Double,
        "target_q"
        | "target_qd"
        | "target_qdd"
        | "target_current"
        | "target_moment"
        | "actual_q"
        | "actual_qd"
        | "actual_current"
        | "actual_current_window"
        | "actual_current_as_torque"
        | "joint_control_output"
        | "actual_TCP_pose"
        | "actual_TCP_speed"
        | "actual_TCP_force"
        | "target_TCP_pose"
        | "target_TCP_speed"
        | "joint_temperatures"
        | "actual_joint_voltage"
        | "payload_inertia"
        | "ft_raw_wrench"
        | "external_force_torque" => Vector6d,
        "actual_tool_accelerometer" | "elbow_position" | "elbow_velocity" | "payload_cog" => {
            Vector3d
        }
        "actual_digital_input_bits" | "actual_digital_output_bits" => Uint64,
        "robot_mode" | "safety_mode" | "safety_status" | "tool_output_voltage" => Int32,
        "runtime_state"
        | "robot_status_bits"
        | "safety_status_bits"
        | "analog_io_types"
        | "euromap67_input_bits"
        | "euromap67_output_bits"
        | "tool_mode"
        | "tool_analog_input_types"
        | "output_bit_registers0_to_31"
        | "output_bit_registers32_to_63"
        | "input_bit_registers0_to_31"
        | "input_bit_registers32_to_63"
        | "script_control_line"
        | "speed_slider_mask" => Uint32,
        "tool_output_mode"
        | "tool_digital_output0_mode"
        | "tool_digital_output1_mode"
        | "standard_digital_output_mask"
        | "standard_digital_output"
        | "configurable_digital_output_mask"
        | "configurable_digital_output"
        | "tool_digital_output_mask"
        | "tool_digital_output"
        | "standard_analog_output_mask"
        | "standard_analog_output_type" => Uint8,
        "joint_mode" => Vector6Int32,
        _ => return register_field_type(name),
    };
    Some(ty)
}

/// Types of `{input,output}_{int,double,bit}_register_N` names.
fn register_field_type(name: &str) -> Option<FieldType> {
    let rest = name
        .strip_prefix("input_")
        .or_else(|| name.strip_prefix("output_"))?;
    let (ty, n, max) = if let Some(n) = rest.strip_prefix("int_register_") {
        (FieldType::Int32, n, 47)
    } else if let Some(n) = rest.strip_prefix("double_register_") {
        (FieldType::Double, n, 47)
    } else if let Some(n) = rest.strip_prefix("bit_register_") {
        (FieldType::Bool, n, 127)
    } else {
        return None;
    };
    let idx: u32 = n.parse().ok()?;
    let in_range = if ty == FieldType::Bool {
        (64..=max).contains(&idx)
    } else {
        idx <= max
    };
    (in_range && !n.starts_with('+') && (n == "0" || !n.starts_with('0'))).then_some(ty)
}

/// A package a client sends to the controller. Borrows from the bytes it was decoded from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ClientPackage<'a> {
    /// `V`: ask for protocol `version`.
    RequestProtocolVersion {
        /// Requested protocol version.
        version: u16,
    },
    /// `v`: ask for the controller's version.
    GetControllerVersion,
    /// `O`: set up an output recipe.
    SetupOutputs {
        /// Output frequency \[Hz\].
        frequency_hz: f64,
        /// Comma-separated field names.
        names: &'a str,
    },
    /// `I`: set up an input recipe.
    SetupInputs {
        /// Comma-separated field names.
        names: &'a str,
    },
    /// `S`: start streaming outputs.
    Start,
    /// `P`: pause streaming outputs.
    Pause,
    /// `U`: an input data package.
    Data(DataPackage<'a>),
    /// `M`: a text message.
    Text(TextMessage<'a>),
}

/// A package a controller sends to the client. Borrows from the bytes it was decoded from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControllerPackage<'a> {
    /// `V` reply.
    ProtocolVersionAccepted(bool),
    /// `v` reply.
    ControllerVersion(ControllerVersion),
    /// `O` reply: recipe id and comma-separated types (or `NOT_FOUND`).
    SetupOutputsReply {
        /// Recipe id (0 when refused).
        recipe_id: u8,
        /// Comma-separated type strings.
        types: &'a str,
    },
    /// `I` reply: recipe id and comma-separated types (or `NOT_FOUND`, `IN_USE`).
    SetupInputsReply {
        /// Recipe id (0 when refused).
        recipe_id: u8,
        /// Comma-separated type strings.
        types: &'a str,
    },
    /// `S` reply.
    StartAccepted(bool),
    /// `P` reply.
    PauseAccepted(bool),
    /// `U`: an output data package.
    Data(DataPackage<'a>),
    /// `M`: a text message.
    Text(TextMessage<'a>),
}

/// The controller's software version.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct ControllerVersion {
    /// Major version (5 for e-Series, 3 for CB3).
    pub major: u32,
    /// Minor version.
    pub minor: u32,
    /// Bug-fix version.
    pub bugfix: u32,
    /// Build number.
    pub build: u32,
}

/// A data package: recipe id and the packed values (decode them with its [`Recipe`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DataPackage<'a> {
    /// Recipe id.
    pub recipe_id: u8,
    /// Packed values, big-endian, in recipe order.
    pub payload: &'a [u8],
}

/// A text message (`M`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TextMessage<'a> {
    /// The message (at most 255 bytes).
    pub message: &'a str,
    /// Its source (at most 255 bytes).
    pub source: &'a str,
    /// Level: 0 exception, 1 error, 2 warning, 3 info.
    pub level: u8,
}

/// Text message levels.
pub mod level {
    /// Exception.
    pub const EXCEPTION: u8 = 0;
    /// Error.
    pub const ERROR: u8 = 1;
    /// Warning.
    pub const WARNING: u8 = 2;
    /// Information.
    pub const INFO: u8 = 3;
}

/// Splits one package off the front of `buf`: `Ok(Some((type, payload, total_len)))`,
/// `Ok(None)` if `buf` holds less than a whole package, or an error if the size field is
/// impossible (below the header length).
pub fn split_package(buf: &[u8]) -> Result<Option<(u8, &[u8], usize)>> {
    let Some(header) = buf.get(..HEADER_LEN) else {
        return Ok(None);
    };
    let size = usize::from(u16::from_be_bytes([
        header.first().copied().unwrap_or(0),
        header.get(1).copied().unwrap_or(0),
    ]));
    if size < HEADER_LEN {
        return Err(RobotIoError::Malformed {
            reason: "size field below header length",
        });
    }
    let kind = header.get(2).copied().unwrap_or(0);
    Ok(buf
        .get(HEADER_LEN..size)
        .map(|payload| (kind, payload, size)))
}

/// Decodes exactly one whole package (`bytes` must be its full length).
fn whole(bytes: &[u8]) -> Result<(u8, &[u8])> {
    match split_package(bytes)? {
        Some((kind, payload, len)) if len == bytes.len() => Ok((kind, payload)),
        Some(_) => Err(RobotIoError::Malformed {
            reason: "trailing bytes after package",
        }),
        None => {
            let needed = take::<2>(bytes, 0, "package")
                .map(|h| usize::from(u16::from_be_bytes(h)))
                .unwrap_or(HEADER_LEN)
                .max(HEADER_LEN);
            Err(RobotIoError::Truncated {
                what: "package",
                needed,
                available: bytes.len(),
            })
        }
    }
}

fn str_of(bytes: &[u8]) -> Result<&str> {
    std::str::from_utf8(bytes).map_err(|_| RobotIoError::Malformed {
        reason: "text is not utf-8",
    })
}

fn u8_reply(payload: &[u8]) -> Result<bool> {
    match payload {
        [b] => Ok(*b != 0),
        [] => Err(RobotIoError::Truncated {
            what: "reply",
            needed: 1,
            available: 0,
        }),
        _ => Err(RobotIoError::Malformed {
            reason: "reply longer than one byte",
        }),
    }
}

fn decode_text(payload: &[u8]) -> Result<TextMessage<'_>> {
    let mut at = 0usize;
    let mut field = |what: &'static str| -> Result<&[u8]> {
        let len = usize::from(take::<1>(payload, at, what)?[0]);
        let s = payload
            .get(at + 1..at + 1 + len)
            .ok_or(RobotIoError::Truncated {
                what,
                needed: at + 1 + len,
                available: payload.len(),
            })?;
        at += 1 + len;
        Ok(s)
    };
    let message = str_of(field("text message")?)?;
    let source = str_of(field("text source")?)?;
    let level = take::<1>(payload, at, "text level")?[0];
    if payload.len() != at + 1 {
        return Err(RobotIoError::Malformed {
            reason: "trailing bytes after text message",
        });
    }
    Ok(TextMessage {
        message,
        source,
        level,
    })
}

fn decode_setup_reply(payload: &[u8]) -> Result<(u8, &str)> {
    let (&id, types) = payload.split_first().ok_or(RobotIoError::Truncated {
        what: "setup reply",
        needed: 1,
        available: 0,
    })?;
    Ok((id, str_of(types)?))
}

fn decode_data(payload: &[u8]) -> Result<DataPackage<'_>> {
    let (&recipe_id, payload) = payload.split_first().ok_or(RobotIoError::Truncated {
        what: "data package",
        needed: 1,
        available: 0,
    })?;
    Ok(DataPackage { recipe_id, payload })
}

/// Writes the header, runs `body`, then patches the size. Errors if the package would
/// exceed the `u16` size.
fn frame(out: &mut Vec<u8>, kind: u8, body: impl FnOnce(&mut Vec<u8>)) -> Result<()> {
    let start = out.len();
    out.extend_from_slice(&[0, 0, kind]);
    body(out);
    let len = out.len() - start;
    let Ok(size) = u16::try_from(len) else {
        out.truncate(start);
        return Err(RobotIoError::Malformed {
            reason: "package longer than 65535 bytes",
        });
    };
    if let Some(s) = out.get_mut(start..start + 2) {
        s.copy_from_slice(&size.to_be_bytes());
    }
    Ok(())
}

fn encode_text(out: &mut Vec<u8>, t: &TextMessage<'_>) -> Result<()> {
    let m = u8::try_from(t.message.len()).map_err(|_| RobotIoError::Malformed {
        reason: "text message longer than 255 bytes",
    })?;
    let s = u8::try_from(t.source.len()).map_err(|_| RobotIoError::Malformed {
        reason: "text source longer than 255 bytes",
    })?;
    frame(out, kind::TEXT_MESSAGE, |o| {
        o.push(m);
        o.extend_from_slice(t.message.as_bytes());
        o.push(s);
        o.extend_from_slice(t.source.as_bytes());
        o.push(t.level);
    })
}

fn check_names(names: &str) -> Result<()> {
    if names.len() > MAX_NAME_LIST_LEN {
        return Err(RobotIoError::Malformed {
            reason: "name list longer than 2048 bytes",
        });
    }
    Ok(())
}

impl<'a> ClientPackage<'a> {
    /// Decodes one whole package sent by a client.
    pub fn decode(bytes: &'a [u8]) -> Result<Self> {
        let (kind, payload) = whole(bytes)?;
        Ok(match kind {
            kind::REQUEST_PROTOCOL_VERSION => {
                let v = take::<2>(payload, 0, "protocol version")?;
                if payload.len() != 2 {
                    return Err(RobotIoError::Malformed {
                        reason: "version request length",
                    });
                }
                ClientPackage::RequestProtocolVersion {
                    version: u16::from_be_bytes(v),
                }
            }
            kind::GET_URCONTROL_VERSION => ClientPackage::GetControllerVersion,
            kind::SETUP_OUTPUTS => {
                let f = take::<8>(payload, 0, "output frequency")?;
                let names = str_of(payload.get(8..).unwrap_or_default())?;
                check_names(names)?;
                ClientPackage::SetupOutputs {
                    frequency_hz: f64::from_be_bytes(f),
                    names,
                }
            }
            kind::SETUP_INPUTS => {
                let names = str_of(payload)?;
                check_names(names)?;
                ClientPackage::SetupInputs { names }
            }
            kind::START => ClientPackage::Start,
            kind::PAUSE => ClientPackage::Pause,
            kind::DATA_PACKAGE => ClientPackage::Data(decode_data(payload)?),
            kind::TEXT_MESSAGE => ClientPackage::Text(decode_text(payload)?),
            other => return Err(RobotIoError::UnexpectedPackage { kind: other }),
        })
    }

    /// Appends the encoded package to `out`.
    pub fn encode(&self, out: &mut Vec<u8>) -> Result<()> {
        match *self {
            ClientPackage::RequestProtocolVersion { version } => {
                frame(out, kind::REQUEST_PROTOCOL_VERSION, |o| {
                    o.extend_from_slice(&version.to_be_bytes())
                })
            }
            ClientPackage::GetControllerVersion => frame(out, kind::GET_URCONTROL_VERSION, |_| {}),
            ClientPackage::SetupOutputs {
                frequency_hz,
                names,
            } => {
                check_names(names)?;
                frame(out, kind::SETUP_OUTPUTS, |o| {
                    o.extend_from_slice(&frequency_hz.to_be_bytes());
                    o.extend_from_slice(names.as_bytes());
                })
            }
            ClientPackage::SetupInputs { names } => {
                check_names(names)?;
                frame(out, kind::SETUP_INPUTS, |o| {
                    o.extend_from_slice(names.as_bytes())
                })
            }
            ClientPackage::Start => frame(out, kind::START, |_| {}),
            ClientPackage::Pause => frame(out, kind::PAUSE, |_| {}),
            ClientPackage::Data(d) => frame(out, kind::DATA_PACKAGE, |o| {
                o.push(d.recipe_id);
                o.extend_from_slice(d.payload);
            }),
            ClientPackage::Text(t) => encode_text(out, &t),
        }
    }
}

impl<'a> ControllerPackage<'a> {
    /// Decodes one whole package sent by a controller.
    pub fn decode(bytes: &'a [u8]) -> Result<Self> {
        let (kind, payload) = whole(bytes)?;
        Ok(match kind {
            kind::REQUEST_PROTOCOL_VERSION => {
                ControllerPackage::ProtocolVersionAccepted(u8_reply(payload)?)
            }
            kind::GET_URCONTROL_VERSION => {
                let w = |i: usize| {
                    take::<4>(payload, 4 * i, "controller version").map(u32::from_be_bytes)
                };
                if payload.len() != 16 {
                    w(3)?;
                    return Err(RobotIoError::Malformed {
                        reason: "controller version length",
                    });
                }
                ControllerPackage::ControllerVersion(ControllerVersion {
                    major: w(0)?,
                    minor: w(1)?,
                    bugfix: w(2)?,
                    build: w(3)?,
                })
            }
            kind::SETUP_OUTPUTS => {
                let (recipe_id, types) = decode_setup_reply(payload)?;
                ControllerPackage::SetupOutputsReply { recipe_id, types }
            }
            kind::SETUP_INPUTS => {
                let (recipe_id, types) = decode_setup_reply(payload)?;
                ControllerPackage::SetupInputsReply { recipe_id, types }
            }
            kind::START => ControllerPackage::StartAccepted(u8_reply(payload)?),
            kind::PAUSE => ControllerPackage::PauseAccepted(u8_reply(payload)?),
            kind::DATA_PACKAGE => ControllerPackage::Data(decode_data(payload)?),
            kind::TEXT_MESSAGE => ControllerPackage::Text(decode_text(payload)?),
            other => return Err(RobotIoError::UnexpectedPackage { kind: other }),
        })
    }

    /// Appends the encoded package to `out`.
    pub fn encode(&self, out: &mut Vec<u8>) -> Result<()> {
        match *self {
            ControllerPackage::ProtocolVersionAccepted(a) => {
                frame(out, kind::REQUEST_PROTOCOL_VERSION, |o| o.push(u8::from(a)))
            }
            ControllerPackage::ControllerVersion(v) => {
                frame(out, kind::GET_URCONTROL_VERSION, |o| {
                    for x in [v.major, v.minor, v.bugfix, v.build] {
                        o.extend_from_slice(&x.to_be_bytes());
                    }
                })
            }
            ControllerPackage::SetupOutputsReply { recipe_id, types } => {
                frame(out, kind::SETUP_OUTPUTS, |o| {
                    o.push(recipe_id);
                    o.extend_from_slice(types.as_bytes());
                })
            }
            ControllerPackage::SetupInputsReply { recipe_id, types } => {
                frame(out, kind::SETUP_INPUTS, |o| {
                    o.push(recipe_id);
                    o.extend_from_slice(types.as_bytes());
                })
            }
            ControllerPackage::StartAccepted(a) => frame(out, kind::START, |o| o.push(u8::from(a))),
            ControllerPackage::PauseAccepted(a) => frame(out, kind::PAUSE, |o| o.push(u8::from(a))),
            ControllerPackage::Data(d) => frame(out, kind::DATA_PACKAGE, |o| {
                o.push(d.recipe_id);
                o.extend_from_slice(d.payload);
            }),
            ControllerPackage::Text(t) => encode_text(out, &t),
        }
    }
}

/// Appends a whole `U` package of `values` for `recipe_id` to `out` (no type check against a
/// recipe; the emulator builds its values from the recipe it answered).
pub fn encode_data_package(recipe_id: u8, values: &[Value], out: &mut Vec<u8>) -> Result<()> {
    frame(out, kind::DATA_PACKAGE, |o| {
        o.push(recipe_id);
        values.iter().for_each(|v| v.encode(o));
    })
}

/// Where one field sits in a data package's payload. `Copy`; precomputed by [`Recipe`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FieldSlot {
    /// Byte offset in the payload (after the recipe id) \[B\].
    pub offset: usize,
    /// The field's type.
    pub ty: FieldType,
}

impl FieldSlot {
    /// Reads this field from `payload`.
    pub fn read(&self, payload: &[u8]) -> Result<Value> {
        Value::decode(self.ty, payload, self.offset)
    }

    /// Reads a `DOUBLE` field (integers and booleans are converted; vectors give component 0).
    pub fn read_f64(&self, payload: &[u8]) -> Result<f64> {
        if self.ty == FieldType::Double {
            return take::<8>(payload, self.offset, "field").map(f64::from_be_bytes);
        }
        self.read(payload).map(|v| v.component(0).unwrap_or(0.0))
    }

    /// Reads the first `N` components into `out` (missing components are left untouched).
    pub fn read_into(&self, payload: &[u8], out: &mut [f64]) -> Result<()> {
        let v = self.read(payload)?;
        for (i, o) in out.iter_mut().enumerate() {
            if let Some(c) = v.component(i) {
                *o = c;
            }
        }
        Ok(())
    }
}

/// A recipe: field names, their types and precomputed offsets. Built once at setup.
#[derive(Debug, Clone, PartialEq)]
pub struct Recipe {
    id: u8,
    names: Vec<String>,
    slots: Vec<FieldSlot>,
    payload_len: usize,
}

impl Recipe {
    /// A recipe of `names` with `types` (same length).
    pub fn new(id: u8, names: &[&str], types: &[FieldType]) -> Result<Recipe> {
        if names.len() != types.len() {
            return Err(RobotIoError::RecipeMismatch {
                reason: format!("{} names but {} types", names.len(), types.len()),
            });
        }
        let mut offset = 0;
        let slots = types
            .iter()
            .map(|&ty| {
                let s = FieldSlot { offset, ty };
                offset += ty.size();
                s
            })
            .collect();
        Ok(Recipe {
            id,
            names: names.iter().map(|s| (*s).to_owned()).collect(),
            slots,
            payload_len: offset,
        })
    }

    /// A recipe from a setup reply: `names` as sent, `types` as the controller answered.
    /// `NOT_FOUND` and `IN_USE` answers become [`RobotIoError::FieldsNotFound`] and
    /// [`RobotIoError::InputsInUse`], naming the fields.
    pub fn from_setup_reply(id: u8, names: &[&str], types: &str) -> Result<Recipe> {
        let answered: Vec<&str> = types.split(',').collect();
        if answered.len() != names.len() {
            return Err(RobotIoError::RecipeMismatch {
                reason: format!(
                    "asked for {} fields, controller answered {} types",
                    names.len(),
                    answered.len()
                ),
            });
        }
        let pick = |tag: &str| -> Vec<String> {
            names
                .iter()
                .zip(&answered)
                .filter(|(_, t)| **t == tag)
                .map(|(n, _)| (*n).to_owned())
                .collect()
        };
        let not_found = pick("NOT_FOUND");
        if !not_found.is_empty() {
            return Err(RobotIoError::FieldsNotFound { fields: not_found });
        }
        let in_use = pick("IN_USE");
        if !in_use.is_empty() {
            return Err(RobotIoError::InputsInUse { fields: in_use });
        }
        let tys = answered
            .iter()
            .map(|t| {
                FieldType::parse(t).ok_or_else(|| RobotIoError::UnknownFieldType {
                    name: (*t).to_owned(),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        if id == 0 {
            return Err(RobotIoError::Refused {
                what: "the recipe (id 0)",
            });
        }
        Recipe::new(id, names, &tys)
    }

    /// Recipe id.
    pub fn id(&self) -> u8 {
        self.id
    }

    /// Field names, in order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Field slots, in order.
    pub fn slots(&self) -> &[FieldSlot] {
        &self.slots
    }

    /// Number of fields.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether the recipe has no fields.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// Payload length of a data package, recipe id excluded \[B\].
    pub fn payload_len(&self) -> usize {
        self.payload_len
    }

    /// Comma-separated names, as sent in a setup package.
    pub fn name_list(&self) -> String {
        self.names.join(",")
    }

    /// Comma-separated type strings, as in a setup reply.
    pub fn type_list(&self) -> String {
        self.slots
            .iter()
            .map(|s| s.ty.as_str())
            .collect::<Vec<_>>()
            .join(",")
    }

    /// The slot of field `name` (look it up once, then read with it each package).
    pub fn slot(&self, name: &str) -> Option<FieldSlot> {
        self.names
            .iter()
            .position(|n| n == name)
            .and_then(|i| self.slots.get(i).copied())
    }

    /// Checks that `data` belongs to this recipe and has the right length; returns its
    /// payload.
    pub fn check<'a>(&self, data: &DataPackage<'a>) -> Result<&'a [u8]> {
        if data.recipe_id != self.id {
            return Err(RobotIoError::RecipeMismatch {
                reason: format!(
                    "package for recipe {}, expected {}",
                    data.recipe_id, self.id
                ),
            });
        }
        if data.payload.len() != self.payload_len {
            return Err(RobotIoError::Truncated {
                what: "data package payload",
                needed: self.payload_len,
                available: data.payload.len(),
            });
        }
        Ok(data.payload)
    }

    /// Decodes every field of `payload` into `out` (caller-owned, at least [`Recipe::len`]
    /// long). Allocates nothing.
    pub fn decode_into(&self, payload: &[u8], out: &mut [Value]) -> Result<()> {
        if payload.len() != self.payload_len {
            return Err(RobotIoError::Truncated {
                what: "data package payload",
                needed: self.payload_len,
                available: payload.len(),
            });
        }
        if out.len() < self.slots.len() {
            return Err(RobotIoError::RecipeMismatch {
                reason: format!(
                    "output buffer holds {} values, recipe has {}",
                    out.len(),
                    self.slots.len()
                ),
            });
        }
        for (slot, o) in self.slots.iter().zip(out.iter_mut()) {
            *o = slot.read(payload)?;
        }
        Ok(())
    }

    /// Appends a whole `U` package with `values` (one per field, matching types) to `out`.
    pub fn encode_values(&self, values: &[Value], out: &mut Vec<u8>) -> Result<()> {
        if values.len() != self.slots.len() {
            return Err(RobotIoError::RecipeMismatch {
                reason: format!("{} values for {} fields", values.len(), self.slots.len()),
            });
        }
        for (i, (v, s)) in values.iter().zip(&self.slots).enumerate() {
            if v.field_type() != s.ty {
                return Err(RobotIoError::RecipeMismatch {
                    reason: format!(
                        "field {} is {}, value is {}",
                        self.names.get(i).map_or("?", String::as_str),
                        s.ty,
                        v.field_type()
                    ),
                });
            }
        }
        let id = self.id;
        frame(out, kind::DATA_PACKAGE, |o| {
            o.push(id);
            values.iter().for_each(|v| v.encode(o));
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn enc_client(p: ClientPackage<'_>) -> Vec<u8> {
        let mut v = Vec::new();
        p.encode(&mut v).unwrap();
        v
    }

    fn enc_ctrl(p: ControllerPackage<'_>) -> Vec<u8> {
        let mut v = Vec::new();
        p.encode(&mut v).unwrap();
        v
    }

    #[test]
    fn request_protocol_version_matches_issue_vector() {
        let bytes = enc_client(ClientPackage::RequestProtocolVersion { version: 2 });
        assert_eq!(bytes, [0x00, 0x05, 0x56, 0x00, 0x02]);
        assert_eq!(
            ClientPackage::decode(&bytes).unwrap(),
            ClientPackage::RequestProtocolVersion { version: 2 }
        );
    }

    #[test]
    fn setup_outputs_matches_issue_vector() {
        let names = "actual_q,actual_qd";
        let bytes = enc_client(ClientPackage::SetupOutputs {
            frequency_hz: 500.0,
            names,
        });
        let mut expected = vec![
            0x00, 0x1d, 0x4f, 0x40, 0x7f, 0x40, 0x00, 0x00, 0x00, 0x00, 0x00,
        ];
        expected.extend_from_slice(names.as_bytes());
        assert_eq!(bytes, expected);
        assert_eq!(bytes.len(), 0x1d);
        assert_eq!(
            ClientPackage::decode(&bytes).unwrap(),
            ClientPackage::SetupOutputs {
                frequency_hz: 500.0,
                names
            }
        );
    }

    #[test]
    fn input_data_package_matches_issue_vector() {
        let recipe = Recipe::new(1, &["input_int_register_24"], &[FieldType::Int32]).unwrap();
        let mut bytes = Vec::new();
        recipe
            .encode_values(&[Value::Int32(1)], &mut bytes)
            .unwrap();
        assert_eq!(bytes, [0x00, 0x08, 0x55, 0x01, 0x00, 0x00, 0x00, 0x01]);
        let ClientPackage::Data(d) = ClientPackage::decode(&bytes).unwrap() else {
            panic!()
        };
        let payload = recipe.check(&d).unwrap();
        assert_eq!(
            recipe
                .slot("input_int_register_24")
                .unwrap()
                .read(payload)
                .unwrap(),
            Value::Int32(1)
        );
    }

    #[test]
    fn hand_built_controller_replies() {
        // V accepted.
        assert_eq!(
            enc_ctrl(ControllerPackage::ProtocolVersionAccepted(true)),
            [0, 4, b'V', 1]
        );
        // v 5.11.3.1234
        let v = ControllerVersion {
            major: 5,
            minor: 11,
            bugfix: 3,
            build: 1234,
        };
        let bytes = enc_ctrl(ControllerPackage::ControllerVersion(v));
        assert_eq!(
            bytes,
            [
                0, 19, b'v', 0, 0, 0, 5, 0, 0, 0, 11, 0, 0, 0, 3, 0, 0, 0x04, 0xd2
            ]
        );
        assert_eq!(
            ControllerPackage::decode(&bytes).unwrap(),
            ControllerPackage::ControllerVersion(v)
        );
        // O reply: recipe 1, VECTOR6D,VECTOR6D
        let bytes = enc_ctrl(ControllerPackage::SetupOutputsReply {
            recipe_id: 1,
            types: "VECTOR6D,VECTOR6D",
        });
        let mut exp = vec![0, 21, b'O', 1];
        exp.extend_from_slice(b"VECTOR6D,VECTOR6D");
        assert_eq!(bytes, exp);
        // I reply with IN_USE.
        let bytes = enc_ctrl(ControllerPackage::SetupInputsReply {
            recipe_id: 0,
            types: "IN_USE",
        });
        assert_eq!(bytes, [0, 10, b'I', 0, b'I', b'N', b'_', b'U', b'S', b'E']);
        assert_eq!(
            ControllerPackage::decode(&bytes).unwrap(),
            ControllerPackage::SetupInputsReply {
                recipe_id: 0,
                types: "IN_USE"
            }
        );
        // S / P replies.
        assert_eq!(
            enc_ctrl(ControllerPackage::StartAccepted(true)),
            [0, 4, b'S', 1]
        );
        assert_eq!(
            enc_ctrl(ControllerPackage::PauseAccepted(false)),
            [0, 4, b'P', 0]
        );
        assert_eq!(
            ControllerPackage::decode(&[0, 4, b'S', 1]).unwrap(),
            ControllerPackage::StartAccepted(true)
        );
        assert_eq!(
            ControllerPackage::decode(&[0, 4, b'P', 0]).unwrap(),
            ControllerPackage::PauseAccepted(false)
        );
        assert_eq!(
            ControllerPackage::decode(&[0, 4, b'V', 0]).unwrap(),
            ControllerPackage::ProtocolVersionAccepted(false)
        );
    }

    #[test]
    fn hand_built_client_requests() {
        assert_eq!(
            enc_client(ClientPackage::GetControllerVersion),
            [0, 3, b'v']
        );
        assert_eq!(enc_client(ClientPackage::Start), [0, 3, b'S']);
        assert_eq!(enc_client(ClientPackage::Pause), [0, 3, b'P']);
        let bytes = enc_client(ClientPackage::SetupInputs {
            names: "input_int_register_24",
        });
        let mut exp = vec![0, 24, b'I'];
        exp.extend_from_slice(b"input_int_register_24");
        assert_eq!(bytes, exp);
        for b in [&[0u8, 3, b'v'][..], &[0, 3, b'S'], &[0, 3, b'P'], &bytes] {
            let p = ClientPackage::decode(b).unwrap();
            assert_eq!(enc_client(p), b);
        }
    }

    #[test]
    fn text_message_round_trip_bytes() {
        let t = TextMessage {
            message: "hi",
            source: "emu",
            level: level::INFO,
        };
        let bytes = enc_ctrl(ControllerPackage::Text(t));
        assert_eq!(bytes, [0, 11, b'M', 2, b'h', b'i', 3, b'e', b'm', b'u', 3]);
        assert_eq!(
            ControllerPackage::decode(&bytes).unwrap(),
            ControllerPackage::Text(t)
        );
        assert_eq!(
            ClientPackage::decode(&bytes).unwrap(),
            ClientPackage::Text(t)
        );
        // Length byte past the end.
        assert!(ControllerPackage::decode(&[0, 5, b'M', 9, b'x']).is_err());
    }

    #[test]
    fn every_field_type_encodes_big_endian_and_decodes_back() {
        let cases: Vec<(Value, Vec<u8>)> = vec![
            (Value::Double(1.0), vec![0x3f, 0xf0, 0, 0, 0, 0, 0, 0]),
            (Value::Uint8(0xab), vec![0xab]),
            (Value::Uint32(0x0102_0304), vec![1, 2, 3, 4]),
            (
                Value::Uint64(0x0102_0304_0506_0708),
                vec![1, 2, 3, 4, 5, 6, 7, 8],
            ),
            (Value::Int32(-2), vec![0xff, 0xff, 0xff, 0xfe]),
            (Value::Bool(true), vec![1]),
            (Value::Vector3d([1.0, -2.0, 0.5]), {
                let mut v = vec![0x3f, 0xf0, 0, 0, 0, 0, 0, 0];
                v.extend([0xc0, 0, 0, 0, 0, 0, 0, 0]);
                v.extend([0x3f, 0xe0, 0, 0, 0, 0, 0, 0]);
                v
            }),
            (
                Value::Vector6d([2.0; 6]),
                [0x40, 0, 0, 0, 0, 0, 0, 0].repeat(6),
            ),
            (Value::Vector6Int32([-1, 0, 1, 2, 3, 4]), {
                let mut v = vec![0xff, 0xff, 0xff, 0xff];
                for x in 0..5u8 {
                    v.extend([0, 0, 0, x]);
                }
                v
            }),
            (Value::Vector6Uint32([7; 6]), [0, 0, 0, 7].repeat(6)),
        ];
        for (value, bytes) in cases {
            let mut out = Vec::new();
            value.encode(&mut out);
            assert_eq!(out, bytes, "{value:?}");
            assert_eq!(out.len(), value.field_type().size());
            assert_eq!(Value::decode(value.field_type(), &bytes, 0).unwrap(), value);
            // One byte short is an error, not a panic.
            assert!(Value::decode(value.field_type(), &bytes[..bytes.len() - 1], 0).is_err());
            assert_eq!(
                FieldType::parse(value.field_type().as_str()),
                Some(value.field_type())
            );
        }
    }

    #[test]
    fn recipe_of_every_type_round_trips_with_offsets() {
        let names: Vec<String> = (0..10).map(|i| format!("f{i}")).collect();
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        let recipe = Recipe::new(3, &names, &FieldType::ALL).unwrap();
        assert_eq!(
            recipe.payload_len(),
            8 + 1 + 4 + 8 + 4 + 1 + 24 + 48 + 24 + 24
        );
        assert_eq!(recipe.slot("f4").unwrap().offset, 8 + 1 + 4 + 8);
        let values = [
            Value::Double(-0.25),
            Value::Uint8(9),
            Value::Uint32(u32::MAX),
            Value::Uint64(u64::MAX),
            Value::Int32(i32::MIN),
            Value::Bool(false),
            Value::Vector3d([1.0, 2.0, 3.0]),
            Value::Vector6d([0.1, 0.2, 0.3, 0.4, 0.5, 0.6]),
            Value::Vector6Int32([1, -1, 2, -2, 3, -3]),
            Value::Vector6Uint32([9, 8, 7, 6, 5, 4]),
        ];
        let mut bytes = Vec::new();
        recipe.encode_values(&values, &mut bytes).unwrap();
        assert_eq!(bytes.len(), 3 + 1 + recipe.payload_len());
        assert_eq!(&bytes[..4], &[0, bytes.len() as u8, b'U', 3]);
        let ControllerPackage::Data(d) = ControllerPackage::decode(&bytes).unwrap() else {
            panic!()
        };
        let payload = recipe.check(&d).unwrap();
        let mut out = [Value::Bool(false); 10];
        recipe.decode_into(payload, &mut out).unwrap();
        assert_eq!(out, values);
        // Wrong type is refused.
        let mut bad = values;
        bad[0] = Value::Int32(0);
        assert!(recipe.encode_values(&bad, &mut Vec::new()).is_err());
        // Wrong recipe id is refused.
        assert!(
            recipe
                .check(&DataPackage {
                    recipe_id: 4,
                    payload
                })
                .is_err()
        );
    }

    #[test]
    fn setup_reply_names_not_found_and_in_use_fields() {
        let err = Recipe::from_setup_reply(
            0,
            &["actual_q", "bogus", "nope"],
            "VECTOR6D,NOT_FOUND,NOT_FOUND",
        )
        .unwrap_err();
        assert!(
            matches!(&err, RobotIoError::FieldsNotFound { fields } if fields == &["bogus", "nope"])
        );
        assert!(err.to_string().contains("bogus, nope"));
        let err = Recipe::from_setup_reply(0, &["input_int_register_24"], "IN_USE").unwrap_err();
        assert!(
            matches!(&err, RobotIoError::InputsInUse { fields } if fields == &["input_int_register_24"])
        );
        let ok =
            Recipe::from_setup_reply(2, &["timestamp", "runtime_state"], "DOUBLE,UINT32").unwrap();
        assert_eq!(
            ok.slot("runtime_state").unwrap(),
            FieldSlot {
                offset: 8,
                ty: FieldType::Uint32
            }
        );
    }

    #[test]
    fn known_field_types() {
        assert_eq!(known_field_type("actual_q"), Some(FieldType::Vector6d));
        assert_eq!(
            known_field_type("joint_mode"),
            Some(FieldType::Vector6Int32)
        );
        assert_eq!(
            known_field_type("input_int_register_24"),
            Some(FieldType::Int32)
        );
        assert_eq!(
            known_field_type("output_double_register_47"),
            Some(FieldType::Double)
        );
        assert_eq!(known_field_type("input_double_register_48"), None);
        assert_eq!(
            known_field_type("input_bit_register_64"),
            Some(FieldType::Bool)
        );
        assert_eq!(known_field_type("input_bit_register_3"), None);
        assert_eq!(known_field_type("input_int_register_024"), None);
        assert_eq!(known_field_type("actual_q_0"), None);
    }

    #[test]
    fn framing_rejects_bad_sizes() {
        assert!(split_package(&[0, 2, b'S']).is_err());
        assert_eq!(split_package(&[0, 5, b'V', 0]).unwrap(), None);
        assert!(ClientPackage::decode(&[0, 5, b'V', 0]).is_err());
        assert!(ClientPackage::decode(&[0, 3, b'S', 9]).is_err());
        assert!(ControllerPackage::decode(&[0, 3, b'X']).is_err());
        assert!(ControllerPackage::decode(&[]).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

        /// Arbitrary bytes never panic either decoder.
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let _ = ClientPackage::decode(&bytes);
            let _ = ControllerPackage::decode(&bytes);
            let _ = split_package(&bytes);
            let recipe = Recipe::new(1, &["a", "b", "c"], &[FieldType::Vector6d, FieldType::Uint32, FieldType::Bool]).unwrap();
            let mut out = [Value::Bool(false); 3];
            let _ = recipe.decode_into(&bytes, &mut out);
            for ty in FieldType::ALL {
                let _ = Value::decode(ty, &bytes, bytes.len() / 2);
            }
        }

        /// Every truncation of a valid package is an error (never a panic, never a wrong
        /// decode), and the size field bounds what a framer would buffer.
        #[test]
        fn truncated_packages_are_errors(
            kind_idx in 0usize..8,
            names in "[a-z_]{0,40}",
            freq in 1.0f64..500.0,
            id in any::<u8>(),
            vals in proptest::collection::vec(any::<f64>(), 0..20),
        ) {
            let payload: Vec<u8> = vals.iter().flat_map(|v| v.to_be_bytes()).collect();
            let mut bytes = Vec::new();
            match kind_idx {
                0 => ClientPackage::RequestProtocolVersion { version: u16::from(id) }.encode(&mut bytes),
                1 => ClientPackage::SetupOutputs { frequency_hz: freq, names: &names }.encode(&mut bytes),
                2 => ClientPackage::SetupInputs { names: &names }.encode(&mut bytes),
                3 => ClientPackage::Data(DataPackage { recipe_id: id, payload: &payload }).encode(&mut bytes),
                4 => ControllerPackage::ControllerVersion(ControllerVersion { major: 5, minor: u32::from(id), bugfix: 0, build: 1 }).encode(&mut bytes),
                5 => ControllerPackage::SetupOutputsReply { recipe_id: id, types: &names }.encode(&mut bytes),
                6 => ControllerPackage::Text(TextMessage { message: &names, source: "x", level: 1 }).encode(&mut bytes),
                _ => ControllerPackage::Data(DataPackage { recipe_id: id, payload: &payload }).encode(&mut bytes),
            }.unwrap();
            let size = usize::from(u16::from_be_bytes([bytes[0], bytes[1]]));
            prop_assert_eq!(size, bytes.len());
            prop_assert!(size <= MAX_PACKAGE_LEN);
            let client_side = kind_idx < 4;
            for cut in 0..bytes.len() {
                let short = &bytes[..cut];
                if client_side {
                    prop_assert!(ClientPackage::decode(short).is_err());
                } else {
                    prop_assert!(ControllerPackage::decode(short).is_err());
                }
                prop_assert_eq!(split_package(short).ok().flatten(), None);
            }
            if client_side {
                let p = ClientPackage::decode(&bytes).unwrap();
                let mut again = Vec::new();
                p.encode(&mut again).unwrap();
                prop_assert_eq!(again, bytes);
            } else {
                let p = ControllerPackage::decode(&bytes).unwrap();
                let mut again = Vec::new();
                p.encode(&mut again).unwrap();
                prop_assert_eq!(again, bytes);
            }
        }
    }
}
