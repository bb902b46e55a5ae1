//! Every output field of UR's RTDE guide as the emulator's [`super::SimBackend`] serves it:
//! the fields the simulated robot publishes ([`RobotState`]), fields derived from them by a
//! simple model (joint torques and currents, temperatures, voltages, the elbow, the target
//! TCP), the inputs a client wrote echoed where a controller echoes them (digital and analog
//! outputs, input bit registers), and a stated default for the rest (a model of those would
//! be pretend). README.md (robot-io) has the table.
//!
//! The model (UR5e):
//! - torque per joint [Nm]: gravity from UR's published link masses and centres of mass
//!   (τ = Σ Jᵢᵀ mᵢ g), plus a diagonal effective inertia times the acceleration and viscous and
//!   Coulomb friction; zero unless the arm is RUNNING (brakes hold it otherwise);
//! - current [A] = torque / a torque constant per joint size (not UR's calibration);
//! - temperature [°C]: first order towards ambient + thermal resistance × copper losses
//!   (R · I²), time constant 300 s;
//! - bus voltage 48 V when powered; robot current = (mechanical + copper + idle power) / 48 V.
//!
//! The model runs only while some client's recipe asks for a derived field
//! ([`SimFields::set_model_needed`]), so plain clients cost the emulator nothing extra.
//! Allocates nothing per cycle.

use nalgebra::{Isometry3, Vector3};

use crate::codec::{FieldType, Value};
use crate::kinematics::{
    FRAME_COUNT, jacobian, link_frames, point_jacobian_from_frames, ur5e_tcp_pose,
};
use crate::types::{Joints, RobotState, robot_mode};

/// Controller cycle [s].
const DT: f64 = 0.002;
/// Gravity [m/s²].
const G: f64 = 9.81;
/// UR5e link masses [kg] (UR's published dynamics parameters).
const MASS: Joints = [3.761, 8.058, 2.846, 1.37, 1.3, 0.365];
/// Centre of mass of link i in frame i (after joint i) [m].
const COM: [[f64; 3]; 6] = [
    [0.0, -0.02561, 0.00193],
    [0.2125, 0.0, 0.11336],
    [0.15, 0.0, 0.0265],
    [0.0, -0.0018, 0.01634],
    [0.0, 0.0018, 0.01634],
    [0.0, 0.0, -0.001159],
];
/// Effective inertia per joint, rotor included [kg m²] (diagonal approximation).
const INERTIA: Joints = [1.6, 1.6, 0.5, 0.06, 0.06, 0.03];
/// Viscous friction [Nm s/rad].
const VISCOUS: Joints = [2.0, 2.0, 1.5, 0.5, 0.5, 0.5];
/// Coulomb friction [Nm].
const COULOMB: Joints = [3.0, 3.0, 2.0, 0.8, 0.8, 0.8];
/// Torque constant incl. gearing [Nm/A] (base and shoulder size 3, elbow size 2, wrists
/// size 1).
const TORQUE_CONSTANT: Joints = [12.0, 12.0, 9.0, 5.0, 5.0, 5.0];
/// Winding resistance [Ω].
const RESISTANCE: f64 = 0.3;
/// Thermal resistance joint → ambient [K/W].
const THERMAL_RESISTANCE: f64 = 8.0;
/// Thermal time constant [s].
const THERMAL_TAU_S: f64 = 300.0;
/// Ambient temperature [°C].
pub const AMBIENT_C: f64 = 25.0;
/// Bus voltage when powered [V].
pub const BUS_V: f64 = 48.0;
/// Idle power of the powered arm [W].
const IDLE_W: f64 = 25.0;
/// `actual_execution_time` served [ms] (a default: the emulator has no real-time thread).
pub const EXECUTION_TIME_MS: f64 = 0.25;
/// Joint mode values (`joint_mode`).
pub mod joint_mode {
    /// Joint powered off.
    pub const POWER_OFF: i32 = 239;
    /// Joint booting.
    pub const BOOTING: i32 = 247;
    /// Joint running.
    pub const RUNNING: i32 = 253;
    /// Joint idle (powered, brakes engaged).
    pub const IDLE: i32 = 255;
}

/// Every output field of UR's RTDE guide the sim serves (besides the registers), with its
/// type, in handle order.
pub const SIM_OUTPUT_FIELDS: [(&str, FieldType); 70] = {
    use FieldType::*;
    [
        ("timestamp", Double),
        ("target_q", Vector6d),
        ("target_qd", Vector6d),
        ("target_qdd", Vector6d),
        ("target_current", Vector6d),
        ("target_moment", Vector6d),
        ("actual_q", Vector6d),
        ("actual_qd", Vector6d),
        ("actual_current", Vector6d),
        ("actual_current_window", Vector6d),
        ("joint_control_output", Vector6d),
        ("actual_TCP_pose", Vector6d),
        ("actual_TCP_speed", Vector6d),
        ("actual_TCP_force", Vector6d),
        ("target_TCP_pose", Vector6d),
        ("target_TCP_speed", Vector6d),
        ("actual_digital_input_bits", Uint64),
        ("joint_temperatures", Vector6d),
        ("actual_execution_time", Double),
        ("robot_mode", Int32),
        ("joint_mode", Vector6Int32),
        ("safety_mode", Int32),
        ("safety_status", Int32),
        ("actual_tool_accelerometer", Vector3d),
        ("speed_scaling", Double),
        ("target_speed_fraction", Double),
        ("actual_momentum", Double),
        ("actual_main_voltage", Double),
        ("actual_robot_voltage", Double),
        ("actual_robot_current", Double),
        ("actual_joint_voltage", Vector6d),
        ("actual_digital_output_bits", Uint64),
        ("runtime_state", Uint32),
        ("elbow_position", Vector3d),
        ("elbow_velocity", Vector3d),
        ("robot_status_bits", Uint32),
        ("safety_status_bits", Uint32),
        ("analog_io_types", Uint32),
        ("standard_analog_input0", Double),
        ("standard_analog_input1", Double),
        ("standard_analog_output0", Double),
        ("standard_analog_output1", Double),
        ("io_current", Double),
        ("euromap67_input_bits", Uint32),
        ("euromap67_output_bits", Uint32),
        ("euromap67_24V_voltage", Double),
        ("euromap67_24V_current", Double),
        ("tool_mode", Uint32),
        ("tool_analog_input_types", Uint32),
        ("tool_analog_input0", Double),
        ("tool_analog_input1", Double),
        ("tool_output_voltage", Int32),
        ("tool_output_current", Double),
        ("tool_temperature", Double),
        ("tcp_force_scalar", Double),
        ("output_bit_registers0_to_31", Uint32),
        ("output_bit_registers32_to_63", Uint32),
        ("input_bit_registers0_to_31", Uint32),
        ("input_bit_registers32_to_63", Uint32),
        ("tool_output_mode", Uint8),
        ("tool_digital_output0_mode", Uint8),
        ("tool_digital_output1_mode", Uint8),
        ("payload", Double),
        ("payload_cog", Vector3d),
        ("payload_inertia", Vector6d),
        ("script_control_line", Uint32),
        ("ft_raw_wrench", Vector6d),
        ("joint_position_deviation_ratio", Double),
        ("collision_detection_ratio", Double),
        ("actual_current_as_torque", Vector6d),
    ]
};

/// The first handle whose field needs the model (handles below are [`RobotState`] fields or
/// defaults that cost nothing).
fn needs_model(name: &str) -> bool {
    matches!(
        name,
        "target_qdd"
            | "target_current"
            | "target_moment"
            | "actual_current"
            | "joint_control_output"
            | "target_TCP_pose"
            | "target_TCP_speed"
            | "joint_temperatures"
            | "actual_tool_accelerometer"
            | "actual_momentum"
            | "actual_robot_current"
            | "elbow_position"
            | "elbow_velocity"
            | "tool_temperature"
            | "actual_current_as_torque"
    )
}

/// What clients wrote that a controller echoes in its outputs (set by the emulator from
/// input recipes).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct IoEcho {
    /// Digital outputs: bits 0–7 standard, 8–15 configurable, 16–17 tool
    /// (`actual_digital_output_bits`).
    pub digital_outputs: u64,
    /// Standard analog outputs 0 and 1 as ratios of full scale [-].
    pub analog_output_ratio: [f64; 2],
    /// Standard analog output types: bit 0 output 0, bit 1 output 1 (1 = voltage, 0 =
    /// current).
    pub analog_output_voltage: u8,
    /// `input_bit_register_0` … `_63`, bit N.
    pub input_bits_low: u64,
}

impl IoEcho {
    /// Standard analog output `i` in its unit: [V] (0–10 V) or [A] (4–20 mA).
    pub fn analog_output(&self, i: usize) -> f64 {
        let r = self.analog_output_ratio.get(i).copied().unwrap_or(0.0);
        if self.analog_output_voltage >> i & 1 == 1 {
            10.0 * r
        } else {
            0.004 + 0.016 * r
        }
    }
}

/// The derived-field model's state.
#[derive(Debug, Clone)]
pub struct SimFields {
    model: bool,
    primed: bool,
    prev_target_qd: Joints,
    prev_actual_qd: Joints,
    target_qdd: Joints,
    target_torque: Joints,
    actual_torque: Joints,
    temperatures: Joints,
    target_tcp_pose: [f64; 6],
    target_tcp_speed: [f64; 6],
    accelerometer: [f64; 3],
    momentum: f64,
    robot_current: f64,
    elbow_position: [f64; 3],
    elbow_velocity: [f64; 3],
}

impl Default for SimFields {
    fn default() -> Self {
        Self {
            model: false,
            primed: false,
            prev_target_qd: [0.0; 6],
            prev_actual_qd: [0.0; 6],
            target_qdd: [0.0; 6],
            target_torque: [0.0; 6],
            actual_torque: [0.0; 6],
            temperatures: [AMBIENT_C; 6],
            target_tcp_pose: [0.0; 6],
            target_tcp_speed: [0.0; 6],
            accelerometer: [0.0, 0.0, G],
            momentum: 0.0,
            robot_current: 0.0,
            elbow_position: [0.0; 3],
            elbow_velocity: [0.0; 3],
        }
    }
}

/// Gravity, inertial and friction torque [Nm] at `q`, `qd`, `qdd`; the momentum norm
/// [kg m/s]; the elbow position [m] and velocity [m/s].
fn dynamics(q: &Joints, qd: &Joints, qdd: &Joints) -> (Joints, f64, [f64; 3], [f64; 3]) {
    let mut frames = [Isometry3::identity(); FRAME_COUNT];
    link_frames(q, &mut frames);
    let qd_v = nalgebra::Vector6::from_column_slice(qd);
    let mut tau = nalgebra::Vector6::zeros();
    let mut p = Vector3::zeros();
    for (i, (m, com)) in MASS.iter().zip(COM).enumerate() {
        let (_, j) = point_jacobian_from_frames(&frames, i + 1, &Vector3::from(com));
        tau += j.transpose() * Vector3::new(0.0, 0.0, m * G);
        p += (j * qd_v) * *m;
    }
    let (elbow, je) = point_jacobian_from_frames(&frames, 2, &Vector3::zeros());
    let ve = je * qd_v;
    let mut out = [0.0; 6];
    for (i, o) in out.iter_mut().enumerate() {
        let v = at(qd, i);
        let coulomb = if v.abs() > 1e-6 {
            at(&COULOMB, i) * v.signum()
        } else {
            0.0
        };
        *o = at(tau.as_slice(), i) + at(&INERTIA, i) * at(qdd, i) + at(&VISCOUS, i) * v + coulomb;
    }
    (
        out,
        p.norm(),
        [elbow.x, elbow.y, elbow.z],
        [ve.x, ve.y, ve.z],
    )
}

/// Component `i` of `a` (0 beyond the end).
fn at(a: &[f64], i: usize) -> f64 {
    a.get(i).copied().unwrap_or(0.0)
}

fn current(torque: &Joints) -> Joints {
    std::array::from_fn(|i| at(torque, i) / at(&TORQUE_CONSTANT, i))
}

impl SimFields {
    /// Handle and type of output field `name` (index in [`SIM_OUTPUT_FIELDS`]); asking for a
    /// derived field switches the model on.
    pub fn handle(&mut self, name: &str) -> Option<(usize, FieldType)> {
        let i = SIM_OUTPUT_FIELDS.iter().position(|(n, _)| *n == name)?;
        if needs_model(name) {
            self.model = true;
        }
        SIM_OUTPUT_FIELDS.get(i).map(|(_, t)| (i, *t))
    }

    /// Whether the model runs (a client asked for a derived field).
    pub fn model_running(&self) -> bool {
        self.model
    }

    /// Runs the model one cycle on the state just published.
    pub fn update(&mut self, s: &RobotState) {
        if !self.model {
            return;
        }
        if !self.primed {
            self.prev_target_qd = s.target_qd;
            self.prev_actual_qd = s.actual_qd;
            self.primed = true;
        }
        let actual_qdd: Joints =
            std::array::from_fn(|i| (at(&s.actual_qd, i) - at(&self.prev_actual_qd, i)) / DT);
        self.target_qdd =
            std::array::from_fn(|i| (at(&s.target_qd, i) - at(&self.prev_target_qd, i)) / DT);
        self.prev_target_qd = s.target_qd;
        self.prev_actual_qd = s.actual_qd;
        let running = s.robot_mode == robot_mode::RUNNING;
        let (tt, _, _, _) = dynamics(&s.target_q, &s.target_qd, &self.target_qdd);
        let (ta, momentum, ep, ev) = dynamics(&s.actual_q, &s.actual_qd, &actual_qdd);
        self.target_torque = if running { tt } else { [0.0; 6] };
        self.actual_torque = if running { ta } else { [0.0; 6] };
        self.momentum = momentum;
        self.elbow_position = ep;
        self.elbow_velocity = ev;
        let i_act = current(&self.actual_torque);
        let mut copper = 0.0;
        for (t, i) in self.temperatures.iter_mut().zip(i_act) {
            let p = RESISTANCE * i * i;
            copper += p;
            let steady = AMBIENT_C + THERMAL_RESISTANCE * p;
            *t += (steady - *t) * DT / THERMAL_TAU_S;
        }
        let mech: f64 = self
            .actual_torque
            .iter()
            .zip(&s.actual_qd)
            .map(|(t, v)| t * v)
            .sum();
        let powered = s.robot_mode >= robot_mode::IDLE;
        self.robot_current = if powered {
            (mech.max(0.0) + copper + IDLE_W) / BUS_V
        } else {
            0.0
        };
        self.target_tcp_pose = ur5e_tcp_pose(&s.target_q);
        let j = jacobian(&s.target_q, &Isometry3::identity());
        let v = j * nalgebra::Vector6::from_column_slice(&s.target_qd);
        self.target_tcp_speed = std::array::from_fn(|i| at(v.as_slice(), i));
        // The accelerometer at rest reads gravity's reaction (+g up) in the tool frame.
        let r = crate::kinematics::pose_from_vector(&s.actual_tcp_pose).rotation;
        let a = r.inverse() * Vector3::new(0.0, 0.0, G);
        self.accelerometer = [a.x, a.y, a.z];
    }

    /// The value of field `handle` ([`SimFields::handle`]) for the published state `s` and
    /// the echoed inputs `io`.
    pub fn read(&self, handle: usize, s: &RobotState, io: &IoEcho) -> Value {
        let powered = s.robot_mode >= robot_mode::IDLE;
        let name = SIM_OUTPUT_FIELDS.get(handle).map_or("", |(n, _)| *n);
        let v6 = Value::Vector6d;
        match name {
            "timestamp" => Value::Double(s.timestamp_s),
            "target_q" => v6(s.target_q),
            "target_qd" => v6(s.target_qd),
            "target_qdd" => v6(self.target_qdd),
            "target_current" | "joint_control_output" => v6(current(&self.target_torque)),
            "target_moment" => v6(self.target_torque),
            "actual_q" => v6(s.actual_q),
            "actual_qd" => v6(s.actual_qd),
            "actual_current" => v6(current(&self.actual_torque)),
            "actual_current_as_torque" => v6(self.actual_torque),
            "actual_TCP_pose" => v6(s.actual_tcp_pose),
            "actual_TCP_speed" => v6(s.actual_tcp_speed),
            "target_TCP_pose" => v6(self.target_tcp_pose),
            "target_TCP_speed" => v6(self.target_tcp_speed),
            "joint_temperatures" => v6(self.temperatures),
            "tool_temperature" => Value::Double(at(&self.temperatures, 5)),
            "actual_execution_time" => Value::Double(EXECUTION_TIME_MS),
            "robot_mode" => Value::Int32(s.robot_mode),
            "joint_mode" => Value::Vector6Int32(
                [match s.robot_mode {
                    robot_mode::RUNNING => joint_mode::RUNNING,
                    robot_mode::IDLE => joint_mode::IDLE,
                    m if m > robot_mode::POWER_OFF => joint_mode::BOOTING,
                    _ => joint_mode::POWER_OFF,
                }; 6],
            ),
            "safety_mode" | "safety_status" => Value::Int32(s.safety_mode),
            "actual_tool_accelerometer" => Value::Vector3d(self.accelerometer),
            "speed_scaling" => Value::Double(s.speed_scaling),
            "target_speed_fraction" => Value::Double(s.target_speed_fraction),
            "actual_momentum" => Value::Double(self.momentum),
            "actual_main_voltage" => Value::Double(BUS_V),
            "actual_robot_voltage" => Value::Double(if powered { BUS_V } else { 0.0 }),
            "actual_robot_current" => Value::Double(self.robot_current),
            "actual_joint_voltage" => v6([if powered { BUS_V } else { 0.0 }; 6]),
            "actual_digital_output_bits" => Value::Uint64(io.digital_outputs),
            "runtime_state" => Value::Uint32(s.runtime_state),
            "elbow_position" => Value::Vector3d(self.elbow_position),
            "elbow_velocity" => Value::Vector3d(self.elbow_velocity),
            "robot_status_bits" => Value::Uint32(s.robot_status_bits),
            "safety_status_bits" => Value::Uint32(s.safety_status_bits),
            "analog_io_types" => Value::Uint32(u32::from(io.analog_output_voltage & 3) << 2),
            "standard_analog_output0" => Value::Double(io.analog_output(0)),
            "standard_analog_output1" => Value::Double(io.analog_output(1)),
            "input_bit_registers0_to_31" => Value::Uint32(io.input_bits_low as u32),
            "input_bit_registers32_to_63" => Value::Uint32((io.input_bits_low >> 32) as u32),
            _ => Value::zero(
                SIM_OUTPUT_FIELDS
                    .get(handle)
                    .map_or(FieldType::Double, |(_, t)| *t),
            ),
        }
    }
}
