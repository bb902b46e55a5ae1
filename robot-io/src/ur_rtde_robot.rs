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
//! # Real-time contract
//! - **The sender thread.** ur_rtde's control calls block and allocate: servoJ and speedJ
//!   wait (up to 3 s) for the script's "ready" on the last state received and write the RTDE
//!   input package to the socket synchronously; stopJ waits for the script's "done"; and
//!   servoJ builds its command and package in vectors (31 `malloc` calls per call, measured by
//!   `robot-io/ffi/tools/alloc_count.c`), which no shim can avoid without reimplementing
//!   ur_rtde's control interface. So [`UrRtdeRobot`] gives the control interface to a thread
//!   of its own (`ur_rtde-send`). [`Robot::send`] writes the command into a triple buffer
//!   (the newest command wins) and wakes that thread: it **never waits and allocates
//!   nothing** on the caller's thread (`robot-io/tests/ur_rtde_backend.rs`,
//!   `the_control_cycle_allocates_nothing_through_the_ur_rtde_backend`, a counting
//!   allocator; no ur_rtde call is made there, so no C++ allocation either). The allocation
//!   and the waits happen on the sender thread. What that costs is counted, never hidden
//!   ([`UrRtdeSendStats`]): a command the thread had no time to take is `superseded`, a
//!   failed call is reported by the next `send`, and a call still running after
//!   [`UrRtdeConfig::call_stuck_after`] makes `send` report the link down.
//! - **Reading.** [`Robot::read_state`] copies ur_rtde's latest sample (its receive thread
//!   fills it; the copy takes that thread's state mutex briefly). It never waits for a new
//!   sample: without one it returns the previous state again (same `timestamp_s`), which the
//!   supervisor's staleness check sees. ur_rtde's getters return `std::vector<double>` by
//!   value and build their field name as a `std::string` each call (20–21 `malloc` calls per
//!   read, measured). The shim does not use them: it reads ur_rtde's own state object
//!   (`robot_state()`, the header-inline `getStateData`) with field names built once and into
//!   vectors of its own that keep their storage, so **a `read_state` allocates nothing** (0
//!   `malloc` calls over 1000 reads: `alloc_count.c`, which `scripts/test-ur-rtde` builds and
//!   runs against `hrc-adapt emulate --sim`, failing on any).
//! - **Pacing.** [`UrRtdeRobot::init_period`] and [`UrRtdeRobot::wait_period`] are ur_rtde's
//!   `initPeriod`/`waitPeriod` (a sleep then a spin to the end of the period given at
//!   construction).
//!
//! The supervisor (crate `safety`) wraps this robot like any other; nothing here bypasses it.

use std::borrow::Cow;
use std::ffi::{CStr, CString, c_char, c_int};
use std::marker::PhantomData;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

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
    /// A control call still running after this long makes [`Robot::send`] report the link
    /// down ([`UrRtdeRobot`]'s sender thread) [s]; default 100 ms, 50 UR periods.
    pub call_stuck_after: Duration,
}

impl UrRtdeConfig {
    /// `host` at 500 Hz, the lower register range.
    pub fn new(host: impl Into<String>) -> Self {
        Self {
            host: host.into(),
            frequency_hz: 500.0,
            upper_range_registers: false,
            call_stuck_after: Duration::from_millis(100),
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

impl Drop for UrRtdeReceiver {
    fn drop(&mut self) {
        // SAFETY: the handle came from urs_receive_new and is freed once, here.
        unsafe { ffi::urs_receive_free(self.h.as_ptr()) }
    }
}

/// A UR arm through ur_rtde: [`UrRtdeReceiver`] for the state and ur_rtde's
/// RTDEControlInterface (its own control script on the controller) for the commands.
///
/// The control interface belongs to a sender thread of its own (see the module docs):
/// [`Robot::send`] hands the command over and returns, and the sender thread makes the
/// ur_rtde call. `Send`, `!Sync`. Dropping it stops the sender thread, which stops ur_rtde's
/// control script and frees the interface.
#[derive(Debug)]
pub struct UrRtdeRobot {
    rx: UrRtdeReceiver,
    /// The control interface, for the stateless `initPeriod`/`waitPeriod` only (every other
    /// call is the sender thread's).
    ctl: NonNull<ffi::UrsControl>,
    tx: SenderLink,
    _not_sync: PhantomData<std::cell::Cell<()>>,
}

// SAFETY: the receive handle is owned exclusively (as for UrRtdeReceiver). The control handle
// is used on the owner's thread only for initPeriod/waitPeriod, which read nothing but the
// period set at construction; every other use is the sender thread's. The handoff types are
// Send.
unsafe impl Send for UrRtdeRobot {}

/// What the ur_rtde sender thread did with the commands handed to it ([`UrRtdeRobot::send_stats`]).
///
/// `handed == sent + failed + superseded + pending`, where `pending` (0 or 1) is a command
/// handed and not yet taken, or in its call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct UrRtdeSendStats {
    /// Commands [`Robot::send`] handed to the sender thread [-].
    pub handed: u64,
    /// ur_rtde calls that succeeded [-].
    pub sent: u64,
    /// ur_rtde calls that failed (refused, threw, or the link was down) [-].
    pub failed: u64,
    /// Commands replaced by a newer one before the sender thread took them (it was still in
    /// an earlier call): never sent [-].
    pub superseded: u64,
    /// The longest ur_rtde call so far [ns].
    pub max_call_ns: u64,
}

/// The newest command for the sender thread, numbered from 1 (0: none yet).
#[derive(Debug, Clone, Copy, Default)]
struct Slot {
    seq: u64,
    cmd: Option<JointCommand>,
}

/// State the control thread and the sender thread share (atomics; the mutex only on the
/// error path).
#[derive(Debug, Default)]
struct Shared {
    stop: AtomicBool,
    /// When the call in progress began [ns since the link's epoch, ≥ 1]; 0 while none runs.
    call_began_ns: AtomicU64,
    sent: AtomicU64,
    failed: AtomicU64,
    superseded: AtomicU64,
    max_call_ns: AtomicU64,
    /// The control interface's link, as the sender thread last saw it.
    connected: AtomicBool,
    /// A failure not yet reported by `send` (the first since the last report), and the flag
    /// that says there is one; both changed under the mutex.
    error: Mutex<Option<RobotIoError>>,
    has_error: AtomicBool,
}

/// The control thread's end of the handoff.
#[derive(Debug)]
struct SenderLink {
    input: triple_buffer::Input<Slot>,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    done: mpsc::Receiver<()>,
    epoch: Instant,
    seq: u64,
    stuck_after_ns: u64,
}

/// The control handle as the sender thread owns it.
struct CtlHandle(NonNull<ffi::UrsControl>);

// SAFETY: the sender thread is the only user of the handle besides the stateless
// initPeriod/waitPeriod (see UrRtdeRobot's Send); ur_rtde's control interface has no thread
// affinity.
unsafe impl Send for CtlHandle {}

/// How long the sender thread sleeps while no command comes before it looks at the link
/// again [s].
const IDLE_CHECK: Duration = Duration::from_millis(20);

/// How long dropping a [`UrRtdeRobot`] waits for the sender thread to finish its call and stop
/// ur_rtde's script [s]; after that the thread is left to finish on its own (a warning says so).
const DROP_WAIT: Duration = Duration::from_secs(2);

/// Nanoseconds from `epoch` to now, at least 1 (0 means "no call") [ns].
fn since_ns(epoch: Instant) -> u64 {
    u64::try_from(epoch.elapsed().as_nanos())
        .unwrap_or(u64::MAX)
        .max(1)
}

/// Whether a call that began at `began_ns` (0: none runs) is stuck at `now_ns`, given the
/// bound `stuck_after_ns` [ns].
fn call_stuck(began_ns: u64, now_ns: u64, stuck_after_ns: u64) -> bool {
    began_ns != 0 && now_ns.saturating_sub(began_ns) > stuck_after_ns
}

/// The error of a failed control call, built on the sender thread.
fn control_error(ctl: *mut ffi::UrsControl, call: &'static str, status: c_int) -> RobotIoError {
    if status == ffi::URS_DISCONNECTED {
        return RobotIoError::LinkDown {
            reason: Cow::Borrowed("ur_rtde's control interface is not connected"),
        };
    }
    // SAFETY: the handle is live (the sender thread frees it only after its loop);
    // last_error returns its NUL-terminated buffer, read before any other call on it.
    let message = unsafe { message(ffi::urs_control_last_error(ctl)) };
    RobotIoError::UrRtde {
        call,
        status,
        message,
    }
}

/// One ur_rtde call for `cmd`: servoJ or speedJ (time = one period), or stopJ (asynchronous).
fn call(ctl: *mut ffi::UrsControl, cmd: &JointCommand, period_s: f64) -> Result<()> {
    let (name, status) = match cmd {
        JointCommand::Servo {
            q,
            lookahead_s,
            gain,
        } => (
            "RTDEControlInterface::servoJ",
            // SAFETY: the handle is live and used by this thread only (initPeriod/waitPeriod
            // aside, which touch no state); `q` points at six f64, which the shim reads.
            unsafe { ffi::urs_control_servo_j(ctl, q.as_ptr(), period_s, *lookahead_s, *gain) },
        ),
        JointCommand::Speed { qd, acc } => (
            "RTDEControlInterface::speedJ",
            // SAFETY: as above; `qd` points at six f64.
            unsafe { ffi::urs_control_speed_j(ctl, qd.as_ptr(), *acc, period_s) },
        ),
        JointCommand::Stop { decel } => (
            "RTDEControlInterface::stopJ",
            // SAFETY: as above.
            unsafe { ffi::urs_control_stop_j(ctl, *decel, 1) },
        ),
    };
    if status == ffi::URS_OK {
        Ok(())
    } else {
        Err(control_error(ctl, name, status))
    }
}

/// The sender thread: takes the newest command, calls ur_rtde, counts and keeps the first
/// unreported failure. Asked to stop, it still sends a command handed before, then stops
/// ur_rtde's script and frees the interface.
fn sender_loop(
    ctl: CtlHandle,
    mut out: triple_buffer::Output<Slot>,
    shared: Arc<Shared>,
    epoch: Instant,
    period_s: f64,
    done: mpsc::SyncSender<()>,
) {
    let h = ctl.0.as_ptr();
    let mut last_seq = 0_u64;
    loop {
        // Read before looking for a command: a command handed before the owner asked the
        // thread to stop (its last Stop, typically) is still sent.
        let stopping = shared.stop.load(Ordering::Acquire);
        if !out.update() {
            if stopping {
                break;
            }
            std::thread::park_timeout(IDLE_CHECK);
            if !out.update() {
                // SAFETY: the handle is live and used by this thread only.
                let up = unsafe { ffi::urs_control_is_connected(h) == 1 };
                shared.connected.store(up, Ordering::Release);
                continue;
            }
        }
        let slot = *out.output_buffer();
        let Some(cmd) = slot.cmd.filter(|_| slot.seq > last_seq) else {
            continue;
        };
        shared
            .superseded
            .fetch_add(slot.seq - last_seq - 1, Ordering::Relaxed);
        last_seq = slot.seq;
        let began = since_ns(epoch);
        shared.call_began_ns.store(began, Ordering::Release);
        let r = call(h, &cmd, period_s);
        let took = since_ns(epoch).saturating_sub(began);
        shared.call_began_ns.store(0, Ordering::Release);
        shared.max_call_ns.fetch_max(took, Ordering::Relaxed);
        match r {
            Ok(()) => {
                shared.sent.fetch_add(1, Ordering::Relaxed);
            }
            Err(e) => {
                shared.failed.fetch_add(1, Ordering::Relaxed);
                let mut slot = shared
                    .error
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                if slot.is_none() {
                    *slot = Some(e);
                    shared.has_error.store(true, Ordering::Release);
                }
            }
        }
        // SAFETY: as above.
        let up = unsafe { ffi::urs_control_is_connected(h) == 1 };
        shared.connected.store(up, Ordering::Release);
    }
    // SAFETY: the handle came from urs_control_new and is freed once, here (the shim stops
    // ur_rtde's script first and catches what that throws); the owner no longer uses it.
    unsafe { ffi::urs_control_free(h) };
    let _ = done.send(());
}

impl UrRtdeRobot {
    /// Connects the receive interface, then the control interface (which uploads ur_rtde's
    /// control script and waits for it to run: seconds, not for the control cycle), and
    /// starts the sender thread.
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
        let shared = Arc::new(Shared::default());
        shared.connected.store(true, Ordering::Release);
        let (input, out) = triple_buffer::triple_buffer(&Slot::default());
        let (done_tx, done) = mpsc::sync_channel(1);
        let epoch = Instant::now();
        let period_s = config.period_s();
        let worker = {
            let shared = Arc::clone(&shared);
            let handle = CtlHandle(ctl);
            std::thread::Builder::new()
                .name("ur_rtde-send".into())
                .spawn(move || sender_loop(handle, out, shared, epoch, period_s, done_tx))
        };
        let thread = match worker {
            Ok(t) => t,
            Err(e) => {
                // SAFETY: the thread did not start, so the handle is still ours alone.
                unsafe { ffi::urs_control_free(ctl.as_ptr()) };
                return Err(RobotIoError::UrRtde {
                    call: "std::thread::spawn (ur_rtde sender)",
                    status: -1,
                    message: e.to_string(),
                });
            }
        };
        Ok(Self {
            rx,
            ctl,
            tx: SenderLink {
                input,
                shared,
                thread: Some(thread),
                done,
                epoch,
                seq: 0,
                stuck_after_ns: u64::try_from(config.call_stuck_after.as_nanos())
                    .unwrap_or(u64::MAX),
            },
            _not_sync: PhantomData,
        })
    }

    /// The receive side.
    pub fn receiver(&mut self) -> &mut UrRtdeReceiver {
        &mut self.rx
    }

    /// What the sender thread did with the commands so far ([`UrRtdeSendStats`]).
    pub fn send_stats(&self) -> UrRtdeSendStats {
        let s = &self.tx.shared;
        UrRtdeSendStats {
            handed: self.tx.seq,
            sent: s.sent.load(Ordering::Relaxed),
            failed: s.failed.load(Ordering::Relaxed),
            superseded: s.superseded.load(Ordering::Relaxed),
            max_call_ns: s.max_call_ns.load(Ordering::Relaxed),
        }
    }

    /// ur_rtde's `initPeriod`: the start of a control cycle, as `steady_clock` time [ns].
    pub fn init_period(&mut self) -> Result<i64> {
        let mut t = 0_i64;
        // SAFETY: the handle is live (the sender thread frees it only after this robot is
        // dropped); initPeriod reads the clock and no state of the interface; `t` is writable.
        let status = unsafe { ffi::urs_control_init_period(self.ctl.as_ptr(), &mut t) };
        self.period_status("RTDEControlInterface::initPeriod", status)?;
        Ok(t)
    }

    /// ur_rtde's `waitPeriod`: waits until one period after `t_start_ns` (from
    /// [`UrRtdeRobot::init_period`]); returns at once when that is past.
    pub fn wait_period(&mut self, t_start_ns: i64) -> Result<()> {
        // SAFETY: as in init_period; waitPeriod reads only the period set at construction.
        let status = unsafe { ffi::urs_control_wait_period(self.ctl.as_ptr(), t_start_ns) };
        self.period_status("RTDEControlInterface::waitPeriod", status)
    }

    fn period_status(&self, call: &'static str, status: c_int) -> Result<()> {
        if status == ffi::URS_OK {
            Ok(())
        } else {
            Err(RobotIoError::UrRtde {
                call,
                status,
                message: String::from("(initPeriod/waitPeriod failed)"),
            })
        }
    }

    /// The first failure of a ur_rtde call not yet reported, taken (so [`Robot::send`] does
    /// not report it again). Never waits: if the sender thread is storing a failure right
    /// now, it is reported at the next call. For a caller that skips `send` for a while
    /// (the trial does not repeat an identical Stop) but must still learn of a failure.
    pub fn take_failure(&mut self) -> Option<RobotIoError> {
        let shared = &self.tx.shared;
        if !shared.has_error.load(Ordering::Acquire) {
            return None;
        }
        // try_lock: the sender thread holds the mutex only to store an error.
        let mut slot = shared.error.try_lock().ok()?;
        shared.has_error.store(false, Ordering::Release);
        slot.take()
    }

    /// Whether both of ur_rtde's interfaces report their links up (the control interface's
    /// as the sender thread saw it after its last call, or within the last 20 ms when idle).
    pub fn is_connected(&mut self) -> bool {
        self.tx.shared.connected.load(Ordering::Acquire) && self.rx.is_connected()
    }
}

impl Robot for UrRtdeRobot {
    /// Copies ur_rtde's latest sample; never waits for a new one; allocates nothing (see the
    /// module docs). [`RobotIoError::LinkDown`] when ur_rtde reports the receive link down.
    fn read_state(&mut self, out: &mut RobotState) -> Result<()> {
        self.rx.read(out)
    }

    /// Hands `cmd` to the sender thread, which makes the ur_rtde call: servoJ (time = one
    /// period), speedJ (time = one period) or stopJ (asynchronous). Never waits and allocates
    /// nothing; a newer command replaces one the sender thread has not taken yet
    /// ([`UrRtdeSendStats::superseded`]).
    ///
    /// Errors, without handing `cmd` over:
    /// - a failure of an earlier call, once: [`RobotIoError::UrRtde`] when ur_rtde refused the
    ///   command or threw, [`RobotIoError::LinkDown`] when its link was down;
    /// - [`RobotIoError::LinkDown`] while a call has not returned for longer than
    ///   [`UrRtdeConfig::call_stuck_after`] (ur_rtde waits on a silent link).
    fn send(&mut self, cmd: &JointCommand) -> Result<()> {
        if let Some(e) = self.take_failure() {
            return Err(e);
        }
        let shared = &self.tx.shared;
        let began = shared.call_began_ns.load(Ordering::Acquire);
        if call_stuck(began, since_ns(self.tx.epoch), self.tx.stuck_after_ns) {
            return Err(RobotIoError::LinkDown {
                reason: Cow::Borrowed(
                    "a ur_rtde control call has not returned within call_stuck_after \
                     (ur_rtde waits on a silent link)",
                ),
            });
        }
        self.tx.seq += 1;
        self.tx.input.write(Slot {
            seq: self.tx.seq,
            cmd: Some(*cmd),
        });
        if let Some(t) = &self.tx.thread {
            t.thread().unpark();
        }
        Ok(())
    }
}

impl Drop for UrRtdeRobot {
    fn drop(&mut self) {
        self.tx.shared.stop.store(true, Ordering::Release);
        let Some(thread) = self.tx.thread.take() else {
            return;
        };
        thread.thread().unpark();
        match self.tx.done.recv_timeout(DROP_WAIT) {
            Ok(()) | Err(mpsc::RecvTimeoutError::Disconnected) => {
                let _ = thread.join();
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                // ur_rtde is stuck in a call (a silent link); joining would block the owner.
                tracing::warn!(
                    "ur_rtde's sender thread is still in a call after {DROP_WAIT:?}; it stops \
                     ur_rtde's script and frees the interface when that call returns"
                );
            }
        }
        let st = self.send_stats();
        if st.failed > 0 || st.superseded > 0 {
            tracing::info!(
                "ur_rtde sender: {} commands handed, {} sent, {} failed, {} superseded, \
                 longest call {:.3} ms",
                st.handed,
                st.sent,
                st.failed,
                st.superseded,
                st.max_call_ns as f64 / 1e6
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_call_is_stuck_only_when_one_runs_beyond_the_bound() {
        // No call runs (0): never stuck, however late.
        assert!(!call_stuck(0, u64::MAX, 100));
        // A call began at 1000 ns, bound 100 ns: stuck after 1100, not at it.
        assert!(!call_stuck(1000, 1050, 100));
        assert!(!call_stuck(1000, 1100, 100));
        assert!(call_stuck(1000, 1101, 100));
        // A clock read before the start (another thread's store raced ahead): not stuck.
        assert!(!call_stuck(1000, 900, 100));
    }
}
