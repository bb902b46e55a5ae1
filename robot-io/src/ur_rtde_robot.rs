//! The ur_rtde backend (feature `ur-rtde`): [`UrRtdeRobot`], a [`Robot`] over SDU's ur_rtde
//! 1.6.5, and [`UrRtdeReceiver`], its receive side alone.
//!
//! ur_rtde is C++; we reach it through a small C shim of our own (`robot-io/ffi/`, compiled
//! by `build.rs` with `-D_GLIBCXX_USE_CXX11_ABI=0` against the wheel's `librtde.so`). The shim
//! has opaque handles, plain arrays and integer status: it catches every C++ exception and
//! keeps its message in the handle, and every failure becomes a [`RobotIoError`]:
//! [`RobotIoError::ConnectionRefused`] or [`RobotIoError::UrRtde`] when an interface cannot be
//! built, [`RobotIoError::LinkDown`] when ur_rtde reports the link down (built without
//! allocating) and [`RobotIoError::UrRtde`] when a call threw or returned false.
//!
//! # What runs on the controller
//! [`UrRtdeRobot`] commands through ur_rtde's RTDEControlInterface, which uploads *ur_rtde's*
//! control script (port 30002/30003) and talks to it over registers 18–47 (or the upper range)
//! — not our `hrc_control` program of [`crate::script`]. The native [`crate::RtdeRobot`]'s
//! servo feedforward (the program extrapolates a late target) has no counterpart: a servoJ
//! target reaches the robot as ur_rtde sends it.
//!
//! # Real-time contract: what holds and what does not
//! - **Blocking.** [`Robot::read_state`] copies ur_rtde's latest sample (its receive thread
//!   fills it; each getter takes that thread's state mutex for a copy). It never waits for a
//!   new sample: without one it returns the previous state again (same `timestamp_s`), which
//!   the supervisor's staleness check sees. [`Robot::send`] calls servoJ/speedJ, which write
//!   the RTDE input package to the socket synchronously (a `write` of a few hundred bytes;
//!   it blocks only when the socket buffer is full). A stop uses `stopJ(decel, asynchronous)`,
//!   which does not wait for the arm to stop.
//! - **Allocation.** ur_rtde's getters return `std::vector<double>` by value and build their
//!   field name as a `std::string` each call (20–21 `malloc` calls per read, measured). The
//!   shim does not use them: it reads ur_rtde's own state object (`robot_state()`, the
//!   header-inline `getStateData`) with field names built once and into vectors of its own
//!   that keep their storage, so **a `read_state` allocates nothing** (0 `malloc` calls over
//!   1000 reads: `robot-io/ffi/tools/alloc_count.c`, a malloc-interposing program that
//!   `scripts/test-ur-rtde` builds and runs against `hrc-adapt emulate --sim`, failing on any).
//!   **`send` does allocate**: ur_rtde's servoJ builds its command and the RTDE input package
//!   in vectors (31 `malloc` calls per servoJ, same program, reported and not judged), which
//!   no shim can avoid without reimplementing ur_rtde's control interface. Rust's counting
//!   allocator does not see C++ `malloc`; on the send side this backend does not meet the
//!   crate's no-allocation rule, unlike [`crate::RtdeRobot`].
//! - **Pacing.** [`UrRtdeRobot::init_period`] and [`UrRtdeRobot::wait_period`] are ur_rtde's
//!   `initPeriod`/`waitPeriod` (a sleep then a spin to the end of the period given at
//!   construction).
//!
//! The supervisor (crate `safety`) wraps this robot like any other; nothing here bypasses it.

use std::borrow::Cow;
use std::ffi::{CStr, CString, c_char, c_int};
use std::marker::PhantomData;
use std::ptr::NonNull;

use crate::{JointCommand, Result, Robot, RobotIoError, RobotState};

mod ffi {
    //! The shim's C interface (`robot-io/ffi/ur_rtde_shim.h`).
    use std::ffi::{c_char, c_int};

    pub(super) const URS_OK: c_int = 0;
    pub(super) const URS_DISCONNECTED: c_int = -3;

    /// `urs_receive` (opaque).
    #[repr(C)]
    pub(super) struct UrsReceive {
        _private: [u8; 0],
    }
    /// `urs_control` (opaque).
    #[repr(C)]
    pub(super) struct UrsControl {
        _private: [u8; 0],
    }

    /// `urs_state`.
    #[repr(C)]
    #[derive(Default)]
    pub(super) struct UrsState {
        pub(super) timestamp_s: f64,
        pub(super) actual_q: [f64; 6],
        pub(super) actual_qd: [f64; 6],
        pub(super) target_q: [f64; 6],
        pub(super) target_qd: [f64; 6],
        pub(super) actual_tcp_pose: [f64; 6],
        pub(super) actual_tcp_speed: [f64; 6],
        pub(super) speed_scaling: f64,
        pub(super) target_speed_fraction: f64,
        pub(super) robot_mode: i32,
        pub(super) safety_mode: i32,
        pub(super) runtime_state: u32,
        pub(super) robot_status_bits: u32,
        pub(super) safety_status_bits: u32,
    }

    unsafe extern "C" {
        pub(super) fn urs_receive_new(
            host: *const c_char,
            frequency_hz: f64,
            err: *mut c_char,
            err_len: usize,
        ) -> *mut UrsReceive;
        pub(super) fn urs_receive_free(h: *mut UrsReceive);
        pub(super) fn urs_receive_read(h: *mut UrsReceive, out: *mut UrsState) -> c_int;
        pub(super) fn urs_receive_is_connected(h: *mut UrsReceive) -> c_int;
        pub(super) fn urs_receive_reconnect(h: *mut UrsReceive) -> c_int;
        pub(super) fn urs_receive_last_error(h: *const UrsReceive) -> *const c_char;

        pub(super) fn urs_control_new(
            host: *const c_char,
            frequency_hz: f64,
            upper_range: c_int,
            err: *mut c_char,
            err_len: usize,
        ) -> *mut UrsControl;
        pub(super) fn urs_control_free(h: *mut UrsControl);
        pub(super) fn urs_control_servo_j(
            h: *mut UrsControl,
            q: *const f64,
            time_s: f64,
            lookahead_s: f64,
            gain: f64,
        ) -> c_int;
        pub(super) fn urs_control_speed_j(
            h: *mut UrsControl,
            qd: *const f64,
            acc: f64,
            time_s: f64,
        ) -> c_int;
        pub(super) fn urs_control_stop_j(
            h: *mut UrsControl,
            decel: f64,
            asynchronous: c_int,
        ) -> c_int;
        pub(super) fn urs_control_init_period(h: *mut UrsControl, t_start_ns: *mut i64) -> c_int;
        pub(super) fn urs_control_wait_period(h: *mut UrsControl, t_start_ns: i64) -> c_int;
        pub(super) fn urs_control_is_connected(h: *mut UrsControl) -> c_int;
        pub(super) fn urs_control_reconnect(h: *mut UrsControl) -> c_int;
        pub(super) fn urs_control_last_error(h: *const UrsControl) -> *const c_char;
    }
}

/// Settings of a [`UrRtdeRobot`] or [`UrRtdeReceiver`].
#[derive(Debug, Clone, PartialEq)]
pub struct UrRtdeConfig {
    /// The controller's address (ur_rtde's ports are fixed: RTDE 30004, script 30002/30003).
    pub host: String,
    /// RTDE output frequency and control period [Hz]; 500 for e-Series.
    pub frequency_hz: f64,
    /// Use the upper range of the input registers (42–47 instead of 18–23), as ur_rtde's
    /// `FLAG_UPPER_RANGE_REGISTERS`.
    pub upper_range_registers: bool,
}

impl UrRtdeConfig {
    /// `host` at 500 Hz, the lower register range.
    pub fn new(host: impl Into<String>) -> Self {
        Self {
            host: host.into(),
            frequency_hz: 500.0,
            upper_range_registers: false,
        }
    }

    /// The control period [s].
    pub fn period_s(&self) -> f64 {
        1.0 / self.frequency_hz
    }

    fn checked(&self) -> Result<CString> {
        if !(self.frequency_hz.is_finite() && self.frequency_hz > 0.0) {
            return Err(RobotIoError::InvalidConfig {
                reason: format!(
                    "ur_rtde frequency must be finite and > 0 Hz, got {}",
                    self.frequency_hz
                ),
            });
        }
        CString::new(self.host.as_str()).map_err(|_| RobotIoError::InvalidConfig {
            reason: "the ur_rtde host contains a NUL byte".to_owned(),
        })
    }
}

/// The error of a constructor that returned null, from the message the shim wrote.
fn construct_error(call: &'static str, host: &str, err: &[c_char]) -> RobotIoError {
    let bytes: Vec<u8> = err
        .iter()
        .take_while(|&&c| c != 0)
        .map(|&c| c as u8)
        .collect();
    let message = String::from_utf8_lossy(&bytes).into_owned();
    if message.contains("Connection refused") || message.contains("Could not connect") {
        return RobotIoError::ConnectionRefused {
            addr: format!("{host}:30004 ({call}: {message})"),
        };
    }
    RobotIoError::UrRtde {
        call,
        status: -1,
        message,
    }
}

/// The message a handle keeps, owned.
///
/// # Safety
/// `p` is null or a NUL-terminated string valid for the duration of the call.
unsafe fn message(p: *const c_char) -> String {
    if p.is_null() {
        return String::from("(no message)");
    }
    // SAFETY: non-null and NUL-terminated by the caller's contract (the handle's buffer).
    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
}

/// ur_rtde's RTDEReceiveInterface alone: reads the state, commands nothing. For `record`,
/// the benchmarks, and inside [`UrRtdeRobot`].
///
/// Owns its handle (freed on drop). `Send` (the trial's control thread owns it) but `!Sync`:
/// the shim's handle is used by one thread at a time.
#[derive(Debug)]
pub struct UrRtdeReceiver {
    h: NonNull<ffi::UrsReceive>,
    raw: ffi::UrsState,
    _not_sync: PhantomData<std::cell::Cell<()>>,
}

impl std::fmt::Debug for ffi::UrsState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UrsState")
            .field("timestamp_s", &self.timestamp_s)
            .finish_non_exhaustive()
    }
}

impl UrRtdeReceiver {
    /// Connects ur_rtde's receive interface to `config.host` and subscribes the fields of
    /// [`RobotState`] at `config.frequency_hz`.
    pub fn connect(config: &UrRtdeConfig) -> Result<Self> {
        let host = config.checked()?;
        let mut err: [c_char; 512] = [0; 512];
        // SAFETY: `host` is a valid C string for the call; `err` is a writable buffer of the
        // length passed. The shim catches every exception.
        let h = unsafe {
            ffi::urs_receive_new(
                host.as_ptr(),
                config.frequency_hz,
                err.as_mut_ptr(),
                err.len(),
            )
        };
        let h = NonNull::new(h)
            .ok_or_else(|| construct_error("RTDEReceiveInterface()", &config.host, &err))?;
        Ok(Self {
            h,
            raw: ffi::UrsState::default(),
            _not_sync: PhantomData,
        })
    }

    fn error(&self, call: &'static str, status: c_int) -> RobotIoError {
        if status == ffi::URS_DISCONNECTED {
            return RobotIoError::LinkDown {
                reason: Cow::Borrowed("ur_rtde's receive interface is not connected"),
            };
        }
        // SAFETY: the handle is live (owned by self); last_error returns its NUL-terminated
        // buffer, read before any other call on it.
        let message = unsafe { message(ffi::urs_receive_last_error(self.h.as_ptr())) };
        RobotIoError::UrRtde {
            call,
            status,
            message,
        }
    }

    /// Copies ur_rtde's latest sample into `out`. Does not wait for a new one (see the module
    /// docs for what it allocates in C++).
    pub fn read(&mut self, out: &mut RobotState) -> Result<()> {
        // SAFETY: the handle is live and used by this thread only; `raw` is a repr(C) struct
        // matching `urs_state`, written in full on success.
        let status = unsafe { ffi::urs_receive_read(self.h.as_ptr(), &mut self.raw) };
        if status != ffi::URS_OK {
            return Err(self.error("RTDEReceiveInterface getters", status));
        }
        let r = &self.raw;
        *out = RobotState {
            timestamp_s: r.timestamp_s,
            actual_q: r.actual_q,
            actual_qd: r.actual_qd,
            target_q: r.target_q,
            target_qd: r.target_qd,
            actual_tcp_pose: r.actual_tcp_pose,
            actual_tcp_speed: r.actual_tcp_speed,
            speed_scaling: r.speed_scaling,
            target_speed_fraction: r.target_speed_fraction,
            robot_mode: r.robot_mode,
            safety_mode: r.safety_mode,
            runtime_state: r.runtime_state,
            robot_status_bits: r.robot_status_bits,
            safety_status_bits: r.safety_status_bits,
        };
        Ok(())
    }

    /// Whether ur_rtde reports its receive link up.
    pub fn is_connected(&mut self) -> bool {
        // SAFETY: the handle is live and used by this thread only.
        unsafe { ffi::urs_receive_is_connected(self.h.as_ptr()) == 1 }
    }

    /// ur_rtde's `reconnect` (blocks while it connects; not for the control cycle).
    pub fn reconnect(&mut self) -> Result<()> {
        // SAFETY: the handle is live and used by this thread only.
        let status = unsafe { ffi::urs_receive_reconnect(self.h.as_ptr()) };
        if status == ffi::URS_OK {
            Ok(())
        } else {
            Err(self.error("RTDEReceiveInterface::reconnect", status))
        }
    }
}

// SAFETY: the handle is owned exclusively (no copies, `!Sync` through the Cell marker), so moving
// it to another thread hands over every use; ur_rtde's interface has no thread affinity (its own
// receive thread synchronises with any caller through its state mutex).
unsafe impl Send for UrRtdeReceiver {}

// SAFETY: as for UrRtdeReceiver: both handles are owned exclusively and used by one thread at a
// time; ur_rtde's control interface has no thread affinity.
unsafe impl Send for UrRtdeRobot {}

impl Drop for UrRtdeReceiver {
    fn drop(&mut self) {
        // SAFETY: the handle came from urs_receive_new and is freed once, here.
        unsafe { ffi::urs_receive_free(self.h.as_ptr()) }
    }
}

/// A UR arm through ur_rtde: [`UrRtdeReceiver`] for the state and ur_rtde's
/// RTDEControlInterface (its own control script on the controller) for the commands.
///
/// Owns both handles (freed on drop: the control script is stopped first); `Send`, `!Sync`.
#[derive(Debug)]
pub struct UrRtdeRobot {
    rx: UrRtdeReceiver,
    ctl: NonNull<ffi::UrsControl>,
    period_s: f64,
    _not_sync: PhantomData<std::cell::Cell<()>>,
}

impl UrRtdeRobot {
    /// Connects the receive interface, then the control interface (which uploads ur_rtde's
    /// control script and waits for it to run: seconds, not for the control cycle).
    pub fn connect(config: &UrRtdeConfig) -> Result<Self> {
        let rx = UrRtdeReceiver::connect(config)?;
        let host = config.checked()?;
        let mut err: [c_char; 512] = [0; 512];
        // SAFETY: `host` is a valid C string for the call; `err` is a writable buffer of the
        // length passed. The shim catches every exception.
        let ctl = unsafe {
            ffi::urs_control_new(
                host.as_ptr(),
                config.frequency_hz,
                c_int::from(config.upper_range_registers),
                err.as_mut_ptr(),
                err.len(),
            )
        };
        let ctl = NonNull::new(ctl)
            .ok_or_else(|| construct_error("RTDEControlInterface()", &config.host, &err))?;
        Ok(Self {
            rx,
            ctl,
            period_s: config.period_s(),
            _not_sync: PhantomData,
        })
    }

    fn error(&self, call: &'static str, status: c_int) -> RobotIoError {
        if status == ffi::URS_DISCONNECTED {
            return RobotIoError::LinkDown {
                reason: Cow::Borrowed("ur_rtde's control interface is not connected"),
            };
        }
        // SAFETY: the handle is live (owned by self); last_error returns its NUL-terminated
        // buffer, read before any other call on it.
        let message = unsafe { message(ffi::urs_control_last_error(self.ctl.as_ptr())) };
        RobotIoError::UrRtde {
            call,
            status,
            message,
        }
    }

    fn status(&self, call: &'static str, status: c_int) -> Result<()> {
        if status == ffi::URS_OK {
            Ok(())
        } else {
            Err(self.error(call, status))
        }
    }

    /// The receive side.
    pub fn receiver(&mut self) -> &mut UrRtdeReceiver {
        &mut self.rx
    }

    /// ur_rtde's `initPeriod`: the start of a control cycle, as `steady_clock` time [ns].
    pub fn init_period(&mut self) -> Result<i64> {
        let mut t = 0_i64;
        // SAFETY: the handle is live and used by this thread only; `t` is writable.
        let status = unsafe { ffi::urs_control_init_period(self.ctl.as_ptr(), &mut t) };
        self.status("RTDEControlInterface::initPeriod", status)?;
        Ok(t)
    }

    /// ur_rtde's `waitPeriod`: waits until one period after `t_start_ns` (from
    /// [`UrRtdeRobot::init_period`]); returns at once when that is past.
    pub fn wait_period(&mut self, t_start_ns: i64) -> Result<()> {
        // SAFETY: the handle is live and used by this thread only.
        let status = unsafe { ffi::urs_control_wait_period(self.ctl.as_ptr(), t_start_ns) };
        self.status("RTDEControlInterface::waitPeriod", status)
    }

    /// Whether both of ur_rtde's interfaces report their links up.
    pub fn is_connected(&mut self) -> bool {
        // SAFETY: the handle is live and used by this thread only.
        let ctl = unsafe { ffi::urs_control_is_connected(self.ctl.as_ptr()) == 1 };
        ctl && self.rx.is_connected()
    }

    /// ur_rtde's `reconnect` of both interfaces (blocks for seconds; not for the control
    /// cycle: the supervisor has stopped the trial when the link is lost).
    pub fn reconnect(&mut self) -> Result<()> {
        self.rx.reconnect()?;
        // SAFETY: the handle is live and used by this thread only.
        let status = unsafe { ffi::urs_control_reconnect(self.ctl.as_ptr()) };
        self.status("RTDEControlInterface::reconnect", status)
    }
}

impl Robot for UrRtdeRobot {
    /// Copies ur_rtde's latest sample; never waits for a new one. Allocates on the C++ heap
    /// (see the module docs). [`RobotIoError::LinkDown`] when ur_rtde reports the receive link
    /// down.
    fn read_state(&mut self, out: &mut RobotState) -> Result<()> {
        self.rx.read(out)
    }

    /// servoJ (time = one period), speedJ (time = one period) or stopJ (asynchronous). Writes
    /// to ur_rtde's socket synchronously; [`RobotIoError::UrRtde`] when ur_rtde refuses the
    /// command or throws (the link is lost, the script stopped).
    fn send(&mut self, cmd: &JointCommand) -> Result<()> {
        let ctl = self.ctl.as_ptr();
        match cmd {
            JointCommand::Servo {
                q,
                lookahead_s,
                gain,
            } => {
                // SAFETY: the handle is live and used by this thread only; `q` points at six
                // f64, which the shim reads.
                let status = unsafe {
                    ffi::urs_control_servo_j(ctl, q.as_ptr(), self.period_s, *lookahead_s, *gain)
                };
                self.status("RTDEControlInterface::servoJ", status)
            }
            JointCommand::Speed { qd, acc } => {
                // SAFETY: as above, `qd` points at six f64.
                let status =
                    unsafe { ffi::urs_control_speed_j(ctl, qd.as_ptr(), *acc, self.period_s) };
                self.status("RTDEControlInterface::speedJ", status)
            }
            JointCommand::Stop { decel } => {
                // SAFETY: the handle is live and used by this thread only.
                let status = unsafe { ffi::urs_control_stop_j(ctl, *decel, 1) };
                self.status("RTDEControlInterface::stopJ", status)
            }
        }
    }
}

impl Drop for UrRtdeRobot {
    fn drop(&mut self) {
        // SAFETY: the handle came from urs_control_new and is freed once, here (the shim stops
        // ur_rtde's script first and catches what that throws).
        unsafe { ffi::urs_control_free(self.ctl.as_ptr()) }
    }
}
