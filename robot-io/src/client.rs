//! [`RtdeClient`]: an async RTDE client (tokio) for UR controllers and the emulator.
//!
//! It negotiates protocol version 2, reads the controller version, sets up one output recipe
//! and any number of input recipes, and then streams. A reader task drains the socket all
//! the time into a ring of preallocated payload slots, so a slow consumer never stalls the
//! controller (a controller drops a client that stops reading). The consumer copies samples
//! into caller-owned [`OutputBuffer`]s: after setup nothing on the receive or send path
//! allocates.
//!
//! When no package arrives for [`ClientConfig::link_loss_periods`] expected periods while
//! streaming, or the socket fails, the link is declared lost. A supervisor task reconnects
//! with exponential backoff, re-sends the same recipes (checking the controller answers the
//! same types), re-sends the last inputs and restarts the stream. Each connection is an
//! *epoch*; a sample's epoch and sequence number come with it.

use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, TryLockError};
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::net::TcpStream;
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::sync::{Notify, mpsc, oneshot};
use tokio::task::JoinHandle;

use crate::codec::{
    ClientPackage, ControllerPackage, ControllerVersion, FieldSlot, MAX_FREQUENCY_HZ,
    PROTOCOL_VERSION, Recipe, Value,
};
use crate::{Result, RobotIoError};

/// Default RTDE port of a UR controller.
pub const RTDE_PORT: u16 = 30004;

/// Settings of an [`RtdeClient`].
#[derive(Debug, Clone, PartialEq)]
pub struct ClientConfig {
    /// Controller host name or IP address.
    pub host: String,
    /// RTDE port (30004 on a controller).
    pub port: u16,
    /// Requested output frequency \[Hz\], in (0, 500] (125 Hz at most on CB3).
    pub frequency_hz: f64,
    /// Output field names (any RTDE outputs).
    pub output_fields: Vec<String>,
    /// Input recipes, each a list of input names (e.g. `input_int_register_24`).
    pub input_recipes: Vec<Vec<String>>,
    /// Oldest controller version accepted, as (major, minor).
    pub min_controller_version: (u32, u32),
    /// Timeout of the TCP connect and of each setup reply.
    pub reply_timeout: Duration,
    /// The link is lost when no package arrives for this many expected periods [-].
    pub link_loss_periods: u32,
    /// Floor of the link-loss timeout, for hosts without real-time scheduling (zero: exactly
    /// `link_loss_periods` periods).
    pub link_loss_min: Duration,
    /// Whether to reconnect after a link loss.
    pub reconnect: bool,
    /// First reconnect delay; doubles up to `backoff_max`.
    pub backoff_initial: Duration,
    /// Longest reconnect delay.
    pub backoff_max: Duration,
    /// Samples buffered for the consumer before the oldest are overwritten [-].
    pub queue_capacity: usize,
}

impl ClientConfig {
    /// A configuration for `host` on port 30004 at 500 Hz, outputs `fields`, no inputs.
    pub fn new(host: impl Into<String>, fields: &[&str]) -> Self {
        Self {
            host: host.into(),
            port: RTDE_PORT,
            frequency_hz: MAX_FREQUENCY_HZ,
            output_fields: fields.iter().map(|s| (*s).to_owned()).collect(),
            input_recipes: Vec::new(),
            min_controller_version: (3, 5),
            reply_timeout: Duration::from_secs(2),
            link_loss_periods: 3,
            link_loss_min: Duration::ZERO,
            reconnect: true,
            backoff_initial: Duration::from_millis(20),
            backoff_max: Duration::from_secs(2),
            queue_capacity: 1024,
        }
    }

    /// The link-loss timeout: `link_loss_periods` periods, at least `link_loss_min`.
    pub fn link_loss_timeout(&self) -> Duration {
        let periods = f64::from(self.link_loss_periods.max(1)) / self.frequency_hz;
        Duration::from_secs_f64(periods).max(self.link_loss_min)
    }

    fn validate(&self) -> Result<()> {
        let bad = |reason: String| Err(RobotIoError::InvalidConfig { reason });
        if !(self.frequency_hz > 0.0 && self.frequency_hz <= MAX_FREQUENCY_HZ) {
            return bad(format!(
                "frequency {} hz is outside (0, 500]",
                self.frequency_hz
            ));
        }
        if self.output_fields.is_empty() {
            return bad("no output fields".into());
        }
        if self.queue_capacity == 0 {
            return bad("queue capacity must be at least 1".into());
        }
        if self.input_recipes.iter().any(Vec::is_empty) {
            return bad("an input recipe has no fields".into());
        }
        Ok(())
    }
}

/// Whether the link is up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkState {
    /// Connected; streaming if started.
    Up,
    /// Lost; reconnecting.
    Reconnecting,
    /// Closed, by [`RtdeClient::close`] or after an unrecoverable error.
    Closed,
}

/// What came with a received sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SampleInfo {
    /// Sequence number over the client's life (0 for the first sample).
    pub seq: u64,
    /// Connection epoch (0 for the first connection, +1 per reconnect).
    pub epoch: u64,
    /// Samples overwritten before the consumer read them, since the previous receive.
    pub dropped: u64,
}

/// A caller-owned copy of one output data package, with typed access by precomputed slot.
#[derive(Debug, Clone)]
pub struct OutputBuffer {
    recipe: Arc<Recipe>,
    payload: Vec<u8>,
    info: SampleInfo,
}

impl OutputBuffer {
    /// The output recipe.
    pub fn recipe(&self) -> &Recipe {
        &self.recipe
    }

    /// The raw payload (values packed in recipe order).
    pub fn payload(&self) -> &[u8] {
        &self.payload
    }

    /// Sequence, epoch and drops of the sample held.
    pub fn info(&self) -> SampleInfo {
        self.info
    }

    /// The slot of field `name`: look it up once, then [`OutputBuffer::read`] each sample.
    pub fn slot(&self, name: &str) -> Option<FieldSlot> {
        self.recipe.slot(name)
    }

    /// The value in `slot`.
    pub fn read(&self, slot: FieldSlot) -> Result<Value> {
        slot.read(&self.payload)
    }

    /// The value of field `name` (a linear search; prefer [`OutputBuffer::slot`] in loops).
    pub fn get(&self, name: &str) -> Result<Value> {
        let slot = self
            .slot(name)
            .ok_or_else(|| RobotIoError::RecipeMismatch {
                reason: format!("field {name} is not in the output recipe"),
            })?;
        self.read(slot)
    }

    /// Decodes every field into `out` (at least as long as the recipe).
    pub fn decode_into(&self, out: &mut [Value]) -> Result<()> {
        self.recipe.decode_into(&self.payload, out)
    }
}

/// Preallocated ring of output payloads, written by the reader task.
#[derive(Debug)]
struct Ring {
    slots: Vec<Vec<u8>>,
    epochs: Vec<u64>,
    /// Sequence number the next sample will get.
    head: u64,
}

/// One input package buffer of an [`InputSlot`].
#[derive(Debug)]
struct InputPackage {
    /// Write number of the package held (0: none, or a write that failed) [-].
    seq: u64,
    /// The whole `U` package, encoded with the recipe id of the first connection (the writer
    /// task patches in the current one).
    bytes: Vec<u8>,
}

/// One input recipe: two package buffers, so that the consumer's write ([`RtdeClient::send_inputs`])
/// never waits for the writer task. The consumer writes the buffer that does not hold the
/// newest package (falling back to the other one if the writer task is reading that one),
/// then publishes it in `newest`; the writer task reads the newest one, and skips it if the
/// consumer holds it (the consumer notifies it again when done).
#[derive(Debug)]
struct InputSlot {
    /// The recipe as set up on the first connection (types never change on a reconnect).
    recipe: Recipe,
    /// The recipe as the controller numbered it on the last (re)connection (not real-time).
    current: Mutex<Recipe>,
    /// The recipe id of the last (re)connection.
    id: AtomicU8,
    halves: [Mutex<InputPackage>; 2],
    /// `seq << 1 | half` of the newest complete package (0: nothing written yet).
    newest: AtomicU64,
    /// Write numbers handed out so far [-].
    writes: AtomicU64,
    /// Write number of the package the writer task sent last on this connection (0: none).
    sent: AtomicU64,
}

impl InputSlot {
    fn new(recipe: Recipe) -> InputSlot {
        let package = || {
            Mutex::new(InputPackage {
                seq: 0,
                bytes: Vec::with_capacity(2 * (recipe.payload_len() + 4)),
            })
        };
        InputSlot {
            id: AtomicU8::new(recipe.id()),
            current: Mutex::new(recipe.clone()),
            halves: [package(), package()],
            recipe,
            newest: AtomicU64::new(0),
            writes: AtomicU64::new(0),
            sent: AtomicU64::new(0),
        }
    }
}

#[derive(Debug)]
struct Status {
    epoch: u64,
    controller_version: ControllerVersion,
    last_message: Option<String>,
}

/// [`LinkState`] as stored in [`Shared::link`].
const LINK_UP: u8 = 0;
const LINK_RECONNECTING: u8 = 1;
const LINK_CLOSED: u8 = 2;

#[derive(Debug)]
struct Shared {
    cfg: ClientConfig,
    output: Arc<Recipe>,
    ring: Mutex<Ring>,
    data_ready: Notify,
    /// Fixed at connect, one per input recipe.
    inputs: Vec<InputSlot>,
    inputs_ready: Notify,
    /// What only set-up and reporting read (the real-time path never locks it).
    status: Mutex<Status>,
    /// The [`LinkState`] (`LINK_*`), read by the real-time path without a lock.
    link: AtomicU8,
    /// Why the client closed, set once before `link` becomes `LINK_CLOSED`.
    closed_reason: OnceLock<Arc<str>>,
    /// The reason when none was set (closed by its owner); built at connect, so reporting it
    /// never allocates.
    closed_default: Arc<str>,
    streaming: AtomicBool,
    reconnects: AtomicU64,
    rejected: AtomicU64,
}

impl Shared {
    fn set_link(&self, state: LinkState) {
        let v = match state {
            LinkState::Up => LINK_UP,
            LinkState::Reconnecting => LINK_RECONNECTING,
            LinkState::Closed => LINK_CLOSED,
        };
        // Closed is final: a late state change never reopens it.
        let _ = self
            .link
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |cur| {
                (cur != LINK_CLOSED).then_some(v)
            });
    }

    /// Closes the client for good with `reason` (the first reason set wins).
    fn close_with(&self, reason: Arc<str>) {
        let _ = self.closed_reason.set(reason);
        self.set_link(LinkState::Closed);
    }

    fn link_state(&self) -> LinkState {
        match self.link.load(Ordering::Acquire) {
            LINK_UP => LinkState::Up,
            LINK_RECONNECTING => LinkState::Reconnecting,
            _ => LinkState::Closed,
        }
    }

    fn closed_error(&self) -> RobotIoError {
        RobotIoError::LinkClosed {
            reason: self
                .closed_reason
                .get()
                .unwrap_or(&self.closed_default)
                .clone(),
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The lock if it is free now (a poisoned lock is taken too: the data it guards is plain
/// bytes and counters, valid after any panic); `None` if another thread holds it.
fn try_lock<T>(m: &Mutex<T>) -> Option<MutexGuard<'_, T>> {
    match m.try_lock() {
        Ok(g) => Some(g),
        Err(TryLockError::Poisoned(p)) => Some(p.into_inner()),
        Err(TryLockError::WouldBlock) => None,
    }
}

#[derive(Debug)]
enum Command {
    Start(oneshot::Sender<Result<()>>),
    Pause(oneshot::Sender<Result<()>>),
}

/// An RTDE client. See the [module docs](self).
#[derive(Debug)]
pub struct RtdeClient {
    shared: Arc<Shared>,
    commands: mpsc::Sender<Command>,
    supervisor: JoinHandle<()>,
    /// Next sequence number the consumer will read.
    next: u64,
}

/// One established connection after the handshake.
#[derive(Debug)]
struct Connection {
    reader: BufReader<OwnedReadHalf>,
    writer: OwnedWriteHalf,
    version: ControllerVersion,
}

/// Reads one whole package into `buf` (cleared first; at most 65535 bytes).
async fn read_package<R: tokio::io::AsyncRead + Unpin>(r: &mut R, buf: &mut Vec<u8>) -> Result<()> {
    let io = |source| RobotIoError::Io {
        context: "reading from the controller".into(),
        source,
    };
    let mut size = [0u8; 2];
    r.read_exact(&mut size).await.map_err(io)?;
    let size = usize::from(u16::from_be_bytes(size));
    if size < crate::codec::HEADER_LEN {
        return Err(RobotIoError::Malformed {
            reason: "size field below header length",
        });
    }
    buf.clear();
    buf.resize(size, 0);
    let (head, rest) = buf.split_at_mut(2.min(size));
    head.copy_from_slice(&u16::try_from(size).unwrap_or(u16::MAX).to_be_bytes());
    r.read_exact(rest).await.map_err(io)?;
    Ok(())
}

async fn write_all(w: &mut OwnedWriteHalf, bytes: &[u8], timeout: Duration) -> Result<()> {
    match tokio::time::timeout(timeout, w.write_all(bytes)).await {
        Ok(r) => r.map_err(|source| RobotIoError::Io {
            context: "writing to the controller".into(),
            source,
        }),
        Err(_) => Err(RobotIoError::Timeout {
            what: "a write to the controller",
            after_ms: ms(timeout),
        }),
    }
}

fn ms(d: Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

/// Sends `pkg` and waits for the first reply that is not a text message.
async fn request(
    conn: &mut Connection,
    pkg: ClientPackage<'_>,
    buf: &mut Vec<u8>,
    timeout: Duration,
    what: &'static str,
) -> Result<()> {
    let mut out = Vec::new();
    pkg.encode(&mut out)?;
    write_all(&mut conn.writer, &out, timeout).await?;
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        match tokio::time::timeout_at(deadline, read_package(&mut conn.reader, buf)).await {
            Ok(r) => r?,
            Err(_) => {
                return Err(RobotIoError::Timeout {
                    what,
                    after_ms: ms(timeout),
                });
            }
        }
        match ControllerPackage::decode(buf)? {
            ControllerPackage::Text(t) => {
                tracing::info!(
                    source = t.source,
                    level = t.level,
                    "controller: {}",
                    t.message
                )
            }
            // Stale data from a previous stream: skip.
            ControllerPackage::Data(_) => {}
            _ => return Ok(()),
        }
    }
}

/// Connects and runs the whole handshake; returns the connection and the recipes as the
/// controller answered them.
async fn handshake(cfg: &ClientConfig) -> Result<(Connection, Recipe, Vec<Recipe>)> {
    let addr = format!("{}:{}", cfg.host, cfg.port);
    let stream = match tokio::time::timeout(cfg.reply_timeout, TcpStream::connect(&addr)).await {
        Ok(r) => r.map_err(|e| RobotIoError::connecting(e, &addr))?,
        Err(_) => {
            return Err(RobotIoError::Timeout {
                what: "the tcp connection",
                after_ms: ms(cfg.reply_timeout),
            });
        }
    };
    stream
        .set_nodelay(true)
        .map_err(|source| RobotIoError::Io {
            context: "setting tcp_nodelay".into(),
            source,
        })?;
    let (r, w) = stream.into_split();
    let mut conn = Connection {
        reader: BufReader::with_capacity(1 << 16, r),
        writer: w,
        version: ControllerVersion::default(),
    };
    let mut buf = Vec::with_capacity(crate::codec::MAX_PACKAGE_LEN);
    let t = cfg.reply_timeout;

    request(
        &mut conn,
        ClientPackage::RequestProtocolVersion {
            version: PROTOCOL_VERSION,
        },
        &mut buf,
        t,
        "the protocol version reply",
    )
    .await?;
    match ControllerPackage::decode(&buf)? {
        ControllerPackage::ProtocolVersionAccepted(true) => {}
        ControllerPackage::ProtocolVersionAccepted(false) => {
            return Err(RobotIoError::ProtocolVersionRejected {
                requested: PROTOCOL_VERSION,
            });
        }
        _ => {
            return Err(RobotIoError::Malformed {
                reason: "unexpected reply to the version request",
            });
        }
    }

    request(
        &mut conn,
        ClientPackage::GetControllerVersion,
        &mut buf,
        t,
        "the controller version",
    )
    .await?;
    let ControllerPackage::ControllerVersion(v) = ControllerPackage::decode(&buf)? else {
        return Err(RobotIoError::Malformed {
            reason: "unexpected reply to the controller version request",
        });
    };
    let (min_major, min_minor) = cfg.min_controller_version;
    if (v.major, v.minor) < (min_major, min_minor) {
        return Err(RobotIoError::ControllerVersionUnsupported {
            major: v.major,
            minor: v.minor,
            min_major,
            min_minor,
        });
    }
    conn.version = v;

    let names: Vec<&str> = cfg.output_fields.iter().map(String::as_str).collect();
    let list = cfg.output_fields.join(",");
    request(
        &mut conn,
        ClientPackage::SetupOutputs {
            frequency_hz: cfg.frequency_hz,
            names: &list,
        },
        &mut buf,
        t,
        "the output setup reply",
    )
    .await?;
    let ControllerPackage::SetupOutputsReply { recipe_id, types } =
        ControllerPackage::decode(&buf)?
    else {
        return Err(RobotIoError::Malformed {
            reason: "unexpected reply to the output setup",
        });
    };
    let output = Recipe::from_setup_reply(recipe_id, &names, types)?;

    let mut inputs = Vec::with_capacity(cfg.input_recipes.len());
    for fields in &cfg.input_recipes {
        let names: Vec<&str> = fields.iter().map(String::as_str).collect();
        let list = fields.join(",");
        request(
            &mut conn,
            ClientPackage::SetupInputs { names: &list },
            &mut buf,
            t,
            "the input setup reply",
        )
        .await?;
        let ControllerPackage::SetupInputsReply { recipe_id, types } =
            ControllerPackage::decode(&buf)?
        else {
            return Err(RobotIoError::Malformed {
                reason: "unexpected reply to the input setup",
            });
        };
        inputs.push(Recipe::from_setup_reply(recipe_id, &names, types)?);
    }
    Ok((conn, output, inputs))
}

async fn start_stream(conn: &mut Connection, timeout: Duration) -> Result<()> {
    let mut buf = Vec::with_capacity(64);
    request(
        conn,
        ClientPackage::Start,
        &mut buf,
        timeout,
        "the start reply",
    )
    .await?;
    match ControllerPackage::decode(&buf)? {
        ControllerPackage::StartAccepted(true) => Ok(()),
        ControllerPackage::StartAccepted(false) => Err(RobotIoError::Refused { what: "start" }),
        _ => Err(RobotIoError::Malformed {
            reason: "unexpected reply to start",
        }),
    }
}

impl RtdeClient {
    /// Connects, negotiates protocol 2, checks the controller version and sets up the
    /// recipes. Does not start streaming: call [`RtdeClient::start`].
    ///
    /// Errors: [`RobotIoError::ConnectionRefused`], [`RobotIoError::ProtocolVersionRejected`],
    /// [`RobotIoError::ControllerVersionUnsupported`], [`RobotIoError::FieldsNotFound`]
    /// (naming the fields), [`RobotIoError::InputsInUse`], [`RobotIoError::Timeout`].
    pub async fn connect(cfg: ClientConfig) -> Result<RtdeClient> {
        cfg.validate()?;
        let (conn, output, inputs) = handshake(&cfg).await?;
        let output = Arc::new(output);
        let cap = cfg.queue_capacity;
        let ring = Ring {
            slots: (0..cap).map(|_| vec![0u8; output.payload_len()]).collect(),
            epochs: vec![0; cap],
            head: 0,
        };
        let inputs = inputs.into_iter().map(InputSlot::new).collect();
        let shared = Arc::new(Shared {
            output,
            ring: Mutex::new(ring),
            data_ready: Notify::new(),
            inputs,
            inputs_ready: Notify::new(),
            status: Mutex::new(Status {
                epoch: 0,
                controller_version: conn.version,
                last_message: None,
            }),
            link: AtomicU8::new(LINK_UP),
            closed_reason: OnceLock::new(),
            closed_default: Arc::from("the client is closed"),
            streaming: AtomicBool::new(false),
            reconnects: AtomicU64::new(0),
            rejected: AtomicU64::new(0),
            cfg,
        });
        let (tx, rx) = mpsc::channel(8);
        let supervisor = tokio::spawn(supervise(shared.clone(), conn, rx));
        Ok(RtdeClient {
            shared,
            commands: tx,
            supervisor,
            next: 0,
        })
    }

    /// The controller's version, as read at the last (re)connection.
    pub fn controller_version(&self) -> ControllerVersion {
        lock(&self.shared.status).controller_version
    }

    /// The output recipe (same across reconnects).
    pub fn output_recipe(&self) -> &Recipe {
        &self.shared.output
    }

    /// The input recipes, in the order of [`ClientConfig::input_recipes`].
    pub fn input_recipe(&self, index: usize) -> Option<Recipe> {
        self.shared
            .inputs
            .get(index)
            .map(|s| lock(&s.current).clone())
    }

    /// A buffer for [`RtdeClient::recv`]. Allocates; create it once.
    pub fn output_buffer(&self) -> OutputBuffer {
        OutputBuffer {
            recipe: self.shared.output.clone(),
            payload: vec![0; self.shared.output.payload_len()],
            info: SampleInfo::default(),
        }
    }

    /// Whether the link is up, reconnecting or closed. Never blocks (one atomic load).
    pub fn link_state(&self) -> LinkState {
        self.shared.link_state()
    }

    /// Reconnections so far.
    pub fn reconnects(&self) -> u64 {
        self.shared.reconnects.load(Ordering::Relaxed)
    }

    /// Received data packages rejected (wrong recipe id or length) and never handed out.
    pub fn rejected_packages(&self) -> u64 {
        self.shared.rejected.load(Ordering::Relaxed)
    }

    /// The last text message the controller sent.
    pub fn last_message(&self) -> Option<String> {
        lock(&self.shared.status).last_message.clone()
    }

    async fn command(&self, make: fn(oneshot::Sender<Result<()>>) -> Command) -> Result<()> {
        let (tx, rx) = oneshot::channel();
        let closed = || self.shared.closed_error();
        self.commands.send(make(tx)).await.map_err(|_| closed())?;
        rx.await.map_err(|_| closed())?
    }

    /// Starts the output stream (and keeps it started across reconnects).
    pub async fn start(&self) -> Result<()> {
        self.command(Command::Start).await
    }

    /// Pauses the output stream.
    pub async fn pause(&self) -> Result<()> {
        self.command(Command::Pause).await
    }

    /// [`RobotIoError::LinkClosed`] once the client is closed for good. Never allocates,
    /// never blocks (atomic loads and a reference count).
    pub(crate) fn fatal(&self) -> Option<RobotIoError> {
        (self.shared.link_state() == LinkState::Closed).then(|| self.shared.closed_error())
    }

    /// Copies the next unread sample into `out`, if any. Never blocks, never allocates.
    ///
    /// # Implementation
    /// It only *tries* the ring's lock: while the reader task holds it (copying a sample in)
    /// it returns `Ok(None)`, as if the sample had not arrived yet; the next call gets it.
    pub fn try_recv(&mut self, out: &mut OutputBuffer) -> Result<Option<SampleInfo>> {
        let Some(ring) = try_lock(&self.shared.ring) else {
            return self.fatal().map_or(Ok(None), Err);
        };
        take(&self.shared, &mut self.next, &ring, out)
    }

    /// Copies the newest sample into `out`, skipping older unread ones (counted as dropped).
    /// `Ok(None)` if nothing new arrived. Never blocks, never allocates; like
    /// [`RtdeClient::try_recv`] it returns `Ok(None)` while the reader task holds the ring.
    pub fn try_latest(&mut self, out: &mut OutputBuffer) -> Result<Option<SampleInfo>> {
        let Some(ring) = try_lock(&self.shared.ring) else {
            return self.fatal().map_or(Ok(None), Err);
        };
        let mut skipped = 0;
        if ring.head > self.next + 1 {
            skipped = ring.head - 1 - self.next;
            self.next = ring.head - 1;
        }
        Ok(
            take(&self.shared, &mut self.next, &ring, out)?.map(|mut i| {
                i.dropped += skipped;
                i
            }),
        )
    }

    /// Copies the newest received sample into `out` without consuming it or any other (the
    /// next [`RtdeClient::try_recv`], [`RtdeClient::try_latest`] or [`RtdeClient::recv`]
    /// returns what it would have returned anyway). `Ok(None)` before the first sample. Never
    /// allocates; it waits for the ring's lock (held by the reader task for one copy), so it
    /// is not for the real-time path.
    pub fn peek_latest(&self, out: &mut OutputBuffer) -> Result<Option<SampleInfo>> {
        let ring = lock(&self.shared.ring);
        let cap = ring.slots.len() as u64;
        let Some(seq) = ring.head.checked_sub(1).filter(|_| cap > 0) else {
            return Ok(None);
        };
        let i = usize::try_from(seq % cap).unwrap_or(0);
        let (Some(src), Some(&epoch)) = (ring.slots.get(i), ring.epochs.get(i)) else {
            return Err(RobotIoError::Malformed {
                reason: "ring index out of range",
            });
        };
        out.payload.copy_from_slice(src);
        out.info = SampleInfo {
            seq,
            epoch,
            dropped: 0,
        };
        Ok(Some(out.info))
    }

    /// Waits for the next sample and copies it into `out`. Allocates nothing.
    pub async fn recv(&mut self, out: &mut OutputBuffer) -> Result<SampleInfo> {
        let shared = self.shared.clone();
        loop {
            let notified = shared.data_ready.notified();
            // The lock is waited for here (not real-time): a `try_lock` that lost to another
            // consumer's `peek_latest` would miss the notification of the sample held.
            let got = take(&shared, &mut self.next, &lock(&shared.ring), out);
            if let Some(info) = got? {
                return Ok(info);
            }
            notified.await;
        }
    }

    /// Like [`RtdeClient::recv`] with a timeout.
    pub async fn recv_timeout(
        &mut self,
        out: &mut OutputBuffer,
        timeout: Duration,
    ) -> Result<SampleInfo> {
        match tokio::time::timeout(timeout, self.recv(out)).await {
            Ok(r) => r,
            Err(_) => Err(RobotIoError::Timeout {
                what: "an output data package",
                after_ms: ms(timeout),
            }),
        }
    }

    /// Sets the inputs of input recipe `index` to `values` (one per field, matching types);
    /// the writer task sends them at once and again after a reconnect (the newest write
    /// wins). Allocates nothing and never waits for a lock (see below).
    ///
    /// # Implementation
    /// Each recipe has two package buffers. The write goes into the one that does not hold
    /// the newest package; if the writer task is reading that one, into the other; the
    /// newest is then published with an atomic store and the writer task woken (tokio's
    /// `Notify`, whose own bookkeeping is a short internal lock that is never held across a
    /// wait). A second thread writing the same recipe at the same moment can find both
    /// buffers taken: that write fails with [`RobotIoError::InputsContended`] and is not
    /// taken. Type errors fail before any buffer changes.
    pub fn send_inputs(&self, index: usize, values: &[Value]) -> Result<()> {
        if let Some(e) = self.fatal() {
            return Err(e);
        }
        let slot = self
            .shared
            .inputs
            .get(index)
            .ok_or_else(|| RobotIoError::RecipeMismatch {
                reason: format!("no input recipe {index}"),
            })?;
        let newest = slot.newest.load(Ordering::Acquire);
        let prefer = if newest == 0 {
            0
        } else {
            1 - (newest & 1) as usize
        };
        let [a, b] = &slot.halves;
        let (first, second) = if prefer == 0 { (a, b) } else { (b, a) };
        let (half, mut pkg) = match try_lock(first) {
            Some(g) => (prefer, g),
            None => match try_lock(second) {
                Some(g) => (1 - prefer, g),
                None => return Err(RobotIoError::InputsContended { index }),
            },
        };
        // Encode after what the buffer holds, so that a type error leaves it as it was.
        let keep = pkg.bytes.len();
        slot.recipe.encode_values(values, &mut pkg.bytes)?;
        pkg.bytes.drain(..keep);
        let seq = slot.writes.fetch_add(1, Ordering::Relaxed) + 1;
        pkg.seq = seq;
        drop(pkg);
        slot.newest.store(seq << 1 | half as u64, Ordering::Release);
        self.shared.inputs_ready.notify_one();
        Ok(())
    }

    /// Closes the connection and stops reconnecting.
    pub async fn close(self) {
        self.supervisor.abort();
        // Let the aborted tasks unwind (closing the socket) before returning.
        tokio::task::yield_now().await;
        self.shared.set_link(LinkState::Closed);
    }
}

impl Drop for RtdeClient {
    fn drop(&mut self) {
        self.supervisor.abort();
    }
}

/// Copies sample `*next` of the locked `ring` into `out` and advances `*next` (to the oldest
/// sample still held, first, if the ring overwrote it: those count as dropped). `Ok(None)`
/// when there is none, [`RobotIoError::LinkClosed`] once the client is closed.
fn take(
    shared: &Shared,
    next: &mut u64,
    ring: &Ring,
    out: &mut OutputBuffer,
) -> Result<Option<SampleInfo>> {
    if *next >= ring.head {
        return if shared.link_state() == LinkState::Closed {
            Err(shared.closed_error())
        } else {
            Ok(None)
        };
    }
    let cap = ring.slots.len() as u64;
    let mut dropped = 0;
    if ring.head - *next > cap {
        dropped = ring.head - cap - *next;
        *next = ring.head - cap;
    }
    let i = usize::try_from(*next % cap).unwrap_or(0);
    let (Some(src), Some(&epoch)) = (ring.slots.get(i), ring.epochs.get(i)) else {
        return Err(RobotIoError::Malformed {
            reason: "ring index out of range",
        });
    };
    out.payload.copy_from_slice(src);
    out.info = SampleInfo {
        seq: *next,
        epoch,
        dropped,
    };
    *next += 1;
    Ok(Some(out.info))
}

/// Why a connection ended.
enum Ended {
    /// The link is lost (socket error, EOF, silence): reconnect.
    Lost(String),
    /// The client was dropped.
    Closed,
}

/// Reader task: drains the socket into the ring; forwards start/pause replies.
async fn reader_task(
    shared: Arc<Shared>,
    mut reader: BufReader<OwnedReadHalf>,
    epoch: u64,
    replies: mpsc::UnboundedSender<ControllerReply>,
) -> String {
    let timeout = shared.cfg.link_loss_timeout();
    let mut buf = Vec::with_capacity(crate::codec::MAX_PACKAGE_LEN);
    loop {
        let r = if shared.streaming.load(Ordering::Acquire) {
            match tokio::time::timeout(timeout, read_package(&mut reader, &mut buf)).await {
                Ok(r) => r,
                Err(_) => {
                    if shared.streaming.load(Ordering::Acquire) {
                        return format!("no package for {} ms", ms(timeout));
                    }
                    continue;
                }
            }
        } else {
            // Paused: no data is expected; wake now and then to re-check.
            match tokio::time::timeout(
                Duration::from_millis(100),
                read_package(&mut reader, &mut buf),
            )
            .await
            {
                Ok(r) => r,
                Err(_) => continue,
            }
        };
        if let Err(e) = r {
            return e.to_string();
        }
        match ControllerPackage::decode(&buf) {
            Ok(ControllerPackage::Data(d)) => {
                if shared.output.check(&d).is_err() {
                    shared.rejected.fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                let mut ring = lock(&shared.ring);
                let cap = ring.slots.len() as u64;
                let i = usize::try_from(ring.head % cap).unwrap_or(0);
                if let Some(slot) = ring.slots.get_mut(i) {
                    slot.copy_from_slice(d.payload);
                }
                if let Some(e) = ring.epochs.get_mut(i) {
                    *e = epoch;
                }
                ring.head += 1;
                drop(ring);
                shared.data_ready.notify_waiters();
            }
            Ok(ControllerPackage::Text(t)) => {
                tracing::info!(
                    source = t.source,
                    level = t.level,
                    "controller: {}",
                    t.message
                );
                lock(&shared.status).last_message = Some(t.message.to_owned());
            }
            Ok(ControllerPackage::StartAccepted(a)) => {
                let _ = replies.send(ControllerReply::Start(a));
            }
            Ok(ControllerPackage::PauseAccepted(a)) => {
                let _ = replies.send(ControllerReply::Pause(a));
            }
            Ok(_) => {}
            Err(e) => return format!("undecodable package: {e}"),
        }
    }
}

#[derive(Debug, Clone, Copy)]
enum ControllerReply {
    Start(bool),
    Pause(bool),
}

/// Writes the dirty input packages.
async fn flush_inputs(
    shared: &Shared,
    writer: &mut OwnedWriteHalf,
    scratch: &mut Vec<u8>,
) -> Result<()> {
    scratch.clear();
    for slot in &shared.inputs {
        let newest = slot.newest.load(Ordering::Acquire);
        let sent = slot.sent.load(Ordering::Acquire);
        if newest >> 1 <= sent {
            continue;
        }
        let [a, b] = &slot.halves;
        // The consumer holds it only while writing a newer one; it notifies again when done.
        let Some(pkg) = try_lock(if newest & 1 == 0 { a } else { b }) else {
            continue;
        };
        if pkg.seq <= sent {
            continue;
        }
        let start = scratch.len();
        scratch.extend_from_slice(&pkg.bytes);
        if let Some(id) = scratch.get_mut(start + 3) {
            *id = slot.id.load(Ordering::Acquire);
        }
        slot.sent.store(pkg.seq, Ordering::Release);
    }
    if scratch.is_empty() {
        return Ok(());
    }
    write_all(writer, scratch, shared.cfg.reply_timeout).await
}

async fn await_reply(
    replies: &mut mpsc::UnboundedReceiver<ControllerReply>,
    timeout: Duration,
    want_start: bool,
) -> Result<()> {
    let what = if want_start { "start" } else { "pause" };
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        let r = tokio::time::timeout_at(deadline, replies.recv()).await;
        match r {
            Err(_) => {
                return Err(RobotIoError::Timeout {
                    what: if want_start {
                        "the start reply"
                    } else {
                        "the pause reply"
                    },
                    after_ms: ms(timeout),
                });
            }
            Ok(None) => {
                return Err(RobotIoError::LinkDown {
                    reason: format!("link lost waiting for the {what} reply").into(),
                });
            }
            Ok(Some(ControllerReply::Start(a))) if want_start => {
                return if a {
                    Ok(())
                } else {
                    Err(RobotIoError::Refused { what: "start" })
                };
            }
            Ok(Some(ControllerReply::Pause(a))) if !want_start => {
                return if a {
                    Ok(())
                } else {
                    Err(RobotIoError::Refused { what: "pause" })
                };
            }
            Ok(Some(_)) => {}
        }
    }
}

/// Runs one connection until it ends.
async fn run_connection(
    shared: &Arc<Shared>,
    conn: Connection,
    epoch: u64,
    commands: &mut mpsc::Receiver<Command>,
) -> Ended {
    let Connection {
        reader, mut writer, ..
    } = conn;
    let (reply_tx, mut replies) = mpsc::unbounded_channel();
    let mut reader = AbortOnDrop(tokio::spawn(reader_task(
        shared.clone(),
        reader,
        epoch,
        reply_tx,
    )));
    let mut scratch = Vec::with_capacity(1024);
    let timeout = shared.cfg.reply_timeout;
    // Re-send the current inputs on every (re)connection.
    for slot in &shared.inputs {
        slot.sent.store(0, Ordering::Release);
    }
    let ended = loop {
        if let Err(e) = flush_inputs(shared, &mut writer, &mut scratch).await {
            break Ended::Lost(e.to_string());
        }
        tokio::select! {
            r = &mut reader.0 => {
                break Ended::Lost(r.unwrap_or_else(|e| format!("reader task failed: {e}")));
            }
            () = shared.inputs_ready.notified() => {}
            cmd = commands.recv() => {
                let Some(cmd) = cmd else { break Ended::Closed };
                let (pkg, tx, start) = match cmd {
                    Command::Start(tx) => (ClientPackage::Start, tx, true),
                    Command::Pause(tx) => (ClientPackage::Pause, tx, false),
                };
                scratch.clear();
                let r = match pkg.encode(&mut scratch) {
                    Ok(()) => write_all(&mut writer, &scratch, timeout).await,
                    Err(e) => Err(e),
                };
                let r = match r {
                    Ok(()) => {
                        if !start {
                            shared.streaming.store(false, Ordering::Release);
                        }
                        let r = await_reply(&mut replies, timeout, start).await;
                        if start && r.is_ok() {
                            shared.streaming.store(true, Ordering::Release);
                        }
                        r
                    }
                    Err(e) => Err(e),
                };
                let lost = matches!(r, Err(RobotIoError::Io { .. } | RobotIoError::LinkDown { .. }));
                let reason = r.as_ref().err().map(ToString::to_string);
                let _ = tx.send(r);
                if lost {
                    break Ended::Lost(reason.unwrap_or_default());
                }
            }
        }
    };
    drop(reader);
    ended
}

/// Aborts the task when dropped (so a dropped client leaves no reader behind).
#[derive(Debug)]
struct AbortOnDrop<T>(JoinHandle<T>);

impl<T> Drop for AbortOnDrop<T> {
    fn drop(&mut self) {
        self.0.abort();
    }
}

/// Supervisor: runs connections and reconnects with backoff.
async fn supervise(shared: Arc<Shared>, first: Connection, mut commands: mpsc::Receiver<Command>) {
    let mut conn = first;
    let mut epoch = 0u64;
    loop {
        let ended = run_connection(&shared, conn, epoch, &mut commands).await;
        let reason = match ended {
            Ended::Closed => {
                shared.set_link(LinkState::Closed);
                return;
            }
            Ended::Lost(reason) => reason,
        };
        let want_streaming = shared.streaming.load(Ordering::Acquire);
        tracing::warn!("rtde link lost ({reason}); reconnecting");
        if !shared.cfg.reconnect {
            shared.close_with(Arc::from(format!(
                "link lost ({reason}), reconnecting disabled"
            )));
            shared.data_ready.notify_waiters();
            return;
        }
        shared.set_link(LinkState::Reconnecting);
        let mut delay = shared.cfg.backoff_initial;
        conn = loop {
            tokio::time::sleep(delay).await;
            delay = (delay * 2).min(shared.cfg.backoff_max);
            // Fail pending commands while down.
            while let Ok(cmd) = commands.try_recv() {
                let (Command::Start(tx) | Command::Pause(tx)) = cmd;
                let _ = tx.send(Err(RobotIoError::LinkDown {
                    reason: "reconnecting".into(),
                }));
            }
            match reestablish(&shared, want_streaming).await {
                Ok(c) => break c,
                Err(
                    e @ (RobotIoError::FieldsNotFound { .. }
                    | RobotIoError::ProtocolVersionRejected { .. }
                    | RobotIoError::ControllerVersionUnsupported { .. }
                    | RobotIoError::RecipeMismatch { .. }),
                ) => {
                    tracing::error!("rtde reconnect failed for good: {e}");
                    shared.close_with(Arc::from(e.to_string()));
                    shared.data_ready.notify_waiters();
                    return;
                }
                Err(e) => {
                    tracing::warn!("rtde reconnect failed: {e}; retrying in {} ms", ms(delay))
                }
            }
        };
        epoch += 1;
        shared.reconnects.fetch_add(1, Ordering::Relaxed);
        let mut s = lock(&shared.status);
        s.epoch = epoch;
        s.controller_version = conn.version;
        drop(s);
        shared.set_link(LinkState::Up);
        tracing::info!("rtde link re-established (epoch {epoch})");
    }
}

/// Reconnects with the same recipes; restarts the stream if it was running.
async fn reestablish(shared: &Shared, want_streaming: bool) -> Result<Connection> {
    let (mut conn, output, inputs) = handshake(&shared.cfg).await?;
    if output.slots() != shared.output.slots() {
        return Err(RobotIoError::RecipeMismatch {
            reason: "the controller answered other output types after reconnecting".into(),
        });
    }
    if inputs
        .iter()
        .zip(&shared.inputs)
        .any(|(new, slot)| new.slots() != slot.recipe.slots())
    {
        return Err(RobotIoError::RecipeMismatch {
            reason: "the controller answered other input types after reconnecting".into(),
        });
    }
    // The controller may hand out other ids: the writer task sends the packages with them.
    for (new, slot) in inputs.into_iter().zip(&shared.inputs) {
        slot.id.store(new.id(), Ordering::Release);
        *lock(&slot.current) = new;
    }
    if want_streaming {
        start_stream(&mut conn, shared.cfg.reply_timeout).await?;
    }
    Ok(conn)
}

#[cfg(test)]
mod tests {
    //! The consumer's calls never wait for a lock the client's tasks take (issue 10's
    //! "never blocks" point for the RTDE side of the control cycle). Each test holds those
    //! locks from the test thread, as a reader or writer task descheduled inside its critical
    //! section would, and runs the consumer's calls on another thread. The channel's 30 s
    //! timeout only detects a deadlock; it is not a speed check.

    use super::*;
    use crate::emulator::{Emulator, EmulatorConfig, SimBackend};
    use crate::sim::{SimConfig, SimRobot};
    use std::sync::mpsc;

    const DEADLOCK: Duration = Duration::from_secs(30);

    fn connected(rt: &tokio::runtime::Runtime) -> (Emulator, RtdeClient) {
        rt.block_on(async {
            let sim = SimRobot::new(SimConfig::ur5e()).unwrap();
            let emu = Emulator::start(EmulatorConfig::ephemeral(), Box::new(SimBackend::new(sim)))
                .await
                .unwrap();
            let mut cfg = ClientConfig::new("127.0.0.1", &["timestamp", "actual_q"]);
            cfg.port = emu.rtde_addr().port();
            cfg.input_recipes = vec![vec!["input_int_register_30".into()]];
            let mut client = RtdeClient::connect(cfg).await.unwrap();
            client.start().await.unwrap();
            let mut out = client.output_buffer();
            client
                .recv_timeout(&mut out, Duration::from_secs(5))
                .await
                .unwrap();
            (emu, client)
        })
    }

    fn runtime() -> tokio::runtime::Runtime {
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap()
    }

    /// Waits until the emulator's `input_int_register_30` reads `v`.
    fn emulator_sees(emu: &Emulator, v: i32) {
        let until = std::time::Instant::now() + DEADLOCK;
        while emu.inputs().int[30] != v {
            assert!(
                std::time::Instant::now() < until,
                "register 30 never became {v}"
            );
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    #[test]
    fn reading_and_writing_never_wait_while_the_tasks_hold_their_locks() {
        let rt = runtime();
        let (emu, mut client) = connected(&rt);
        let shared = Arc::clone(&client.shared);
        client.send_inputs(0, &[Value::Int32(1)]).unwrap();
        emulator_sees(&emu, 1);
        // Both locks a reader task takes, and the input buffer holding the newest package
        // (the one the writer task reads).
        let ring = lock(&shared.ring);
        let status = lock(&shared.status);
        let newest = shared.inputs[0].newest.load(Ordering::Acquire);
        let reading = lock(&shared.inputs[0].halves[(newest & 1) as usize]);
        let (tx, rx) = mpsc::channel();
        let worker = std::thread::spawn(move || {
            let mut out = client.output_buffer();
            let r = (
                client.link_state(),
                client.try_latest(&mut out).map(|i| i.is_some()),
                client.try_recv(&mut out).map(|i| i.is_some()),
                client.send_inputs(0, &[Value::Int32(2)]),
                client.send_inputs(0, &[Value::Int32(3)]),
            );
            tx.send(format!("{r:?}")).unwrap();
            client
        });
        let got = rx
            .recv_timeout(DEADLOCK)
            .expect("a consumer call waited for a task's lock");
        // The ring was held: no sample handed out (as if none had arrived yet); both writes
        // were taken into the free buffer.
        assert_eq!(got, "(Up, Ok(false), Ok(false), Ok(()), Ok(()))");
        drop((ring, status, reading));
        let mut client = worker.join().unwrap();
        // Nothing was lost: the newest write reaches the controller, and samples flow.
        rt.block_on(async { shared.inputs_ready.notify_one() });
        emulator_sees(&emu, 3);
        let mut out = client.output_buffer();
        let until = std::time::Instant::now() + DEADLOCK;
        while client.try_latest(&mut out).unwrap().is_none() {
            assert!(
                std::time::Instant::now() < until,
                "no sample after the ring was released"
            );
            std::thread::sleep(Duration::from_millis(1));
        }
        emu.shutdown();
    }

    #[test]
    fn a_write_is_refused_only_while_both_buffers_are_being_used() {
        let rt = runtime();
        let (emu, client) = connected(&rt);
        let shared = Arc::clone(&client.shared);
        let both = (
            lock(&shared.inputs[0].halves[0]),
            lock(&shared.inputs[0].halves[1]),
        );
        let (tx, rx) = mpsc::channel();
        let worker = std::thread::spawn(move || {
            let r = client.send_inputs(0, &[Value::Int32(7)]);
            tx.send(format!("{r:?}")).unwrap();
            client
        });
        let got = rx.recv_timeout(DEADLOCK).expect("send_inputs waited");
        assert_eq!(got, "Err(InputsContended { index: 0 })");
        drop(both);
        let client = worker.join().unwrap();
        client.send_inputs(0, &[Value::Int32(7)]).unwrap();
        emulator_sees(&emu, 7);
        // A type error changes nothing: the newest package is still 7's.
        assert!(client.send_inputs(0, &[Value::Double(1.0)]).is_err());
        rt.block_on(async { shared.inputs_ready.notify_one() });
        std::thread::sleep(Duration::from_millis(20));
        assert_eq!(emu.inputs().int[30], 7);
        emu.shutdown();
    }

    #[test]
    fn a_reconnection_resends_the_newest_inputs_with_the_new_recipe_id() {
        let rt = runtime();
        let (emu, client) = connected(&rt);
        client.send_inputs(0, &[Value::Int32(12)]).unwrap();
        emulator_sees(&emu, 12);
        let written = emu.inputs().int_written[30];
        emu.cut_rtde_links();
        let until = std::time::Instant::now() + DEADLOCK;
        while client.reconnects() == 0 {
            assert!(std::time::Instant::now() < until, "never reconnected");
            std::thread::sleep(Duration::from_millis(5));
        }
        // No new write: the new connection's writer task sends the newest package again,
        // and the controller takes it (so it carried the recipe id of the new session).
        while emu.inputs().int_written[30] == written {
            assert!(
                std::time::Instant::now() < until,
                "the inputs were not re-sent"
            );
            std::thread::sleep(Duration::from_millis(2));
        }
        assert_eq!(emu.inputs().int[30], 12);
        assert_eq!(
            client.input_recipe(0).map(|r| r.id()),
            Some(client.shared.inputs[0].id.load(Ordering::Acquire))
        );
        emu.shutdown();
    }
}
