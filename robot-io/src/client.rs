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

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
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

#[derive(Debug)]
struct InputSlot {
    recipe: Recipe,
    package: Vec<u8>,
    dirty: bool,
}

#[derive(Debug)]
struct Status {
    state: LinkState,
    epoch: u64,
    controller_version: ControllerVersion,
    /// Why the client is closed, once it is (built at connect, so reporting it never
    /// allocates).
    closed_reason: Arc<str>,
    last_message: Option<String>,
}

#[derive(Debug)]
struct Shared {
    cfg: ClientConfig,
    output: Arc<Recipe>,
    ring: Mutex<Ring>,
    data_ready: Notify,
    inputs: Mutex<Vec<InputSlot>>,
    inputs_ready: Notify,
    status: Mutex<Status>,
    streaming: AtomicBool,
    reconnects: AtomicU64,
    rejected: AtomicU64,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
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
        let inputs = inputs
            .into_iter()
            .map(|recipe| {
                let package = Vec::with_capacity(recipe.payload_len() + 4);
                InputSlot {
                    recipe,
                    package,
                    dirty: false,
                }
            })
            .collect();
        let shared = Arc::new(Shared {
            output,
            ring: Mutex::new(ring),
            data_ready: Notify::new(),
            inputs: Mutex::new(inputs),
            inputs_ready: Notify::new(),
            status: Mutex::new(Status {
                state: LinkState::Up,
                epoch: 0,
                controller_version: conn.version,
                closed_reason: Arc::from("the client is closed"),
                last_message: None,
            }),
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
        lock(&self.shared.inputs)
            .get(index)
            .map(|s| s.recipe.clone())
    }

    /// A buffer for [`RtdeClient::recv`]. Allocates; create it once.
    pub fn output_buffer(&self) -> OutputBuffer {
        OutputBuffer {
            recipe: self.shared.output.clone(),
            payload: vec![0; self.shared.output.payload_len()],
            info: SampleInfo::default(),
        }
    }

    /// Whether the link is up, reconnecting or closed.
    pub fn link_state(&self) -> LinkState {
        lock(&self.shared.status).state
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
        let closed = || RobotIoError::LinkClosed {
            reason: lock(&self.shared.status).closed_reason.clone(),
        };
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

    /// [`RobotIoError::LinkClosed`] once the client is closed for good. Never allocates.
    pub(crate) fn fatal(&self) -> Option<RobotIoError> {
        let s = lock(&self.shared.status);
        (s.state == LinkState::Closed).then(|| RobotIoError::LinkClosed {
            reason: s.closed_reason.clone(),
        })
    }

    /// Copies the next unread sample into `out`, if any. Never blocks, never allocates.
    pub fn try_recv(&mut self, out: &mut OutputBuffer) -> Result<Option<SampleInfo>> {
        let ring = lock(&self.shared.ring);
        if self.next >= ring.head {
            drop(ring);
            return self.fatal().map_or(Ok(None), Err);
        }
        let cap = ring.slots.len() as u64;
        let mut dropped = 0;
        if ring.head - self.next > cap {
            dropped = ring.head - cap - self.next;
            self.next = ring.head - cap;
        }
        let i = usize::try_from(self.next % cap).unwrap_or(0);
        let (Some(src), Some(&epoch)) = (ring.slots.get(i), ring.epochs.get(i)) else {
            return Err(RobotIoError::Malformed {
                reason: "ring index out of range",
            });
        };
        out.payload.copy_from_slice(src);
        out.info = SampleInfo {
            seq: self.next,
            epoch,
            dropped,
        };
        self.next += 1;
        Ok(Some(out.info))
    }

    /// Copies the newest sample into `out`, skipping older unread ones (counted as dropped).
    /// `Ok(None)` if nothing new arrived. Never blocks, never allocates.
    pub fn try_latest(&mut self, out: &mut OutputBuffer) -> Result<Option<SampleInfo>> {
        let head = lock(&self.shared.ring).head;
        if head > self.next + 1 {
            let skipped = head - 1 - self.next;
            self.next = head - 1;
            return Ok(self.try_recv(out)?.map(|mut i| {
                i.dropped += skipped;
                i
            }));
        }
        self.try_recv(out)
    }

    /// Copies the newest received sample into `out` without consuming it or any other (the
    /// next [`RtdeClient::try_recv`], [`RtdeClient::try_latest`] or [`RtdeClient::recv`]
    /// returns what it would have returned anyway). `Ok(None)` before the first sample. Never
    /// blocks, never allocates.
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
            if let Some(info) = self.try_recv(out)? {
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
    /// the writer task sends them at once and again after a reconnect. Never blocks on the
    /// network; allocates nothing once the first package of that recipe has been encoded.
    pub fn send_inputs(&self, index: usize, values: &[Value]) -> Result<()> {
        if let Some(e) = self.fatal() {
            return Err(e);
        }
        let mut inputs = lock(&self.shared.inputs);
        let slot = inputs
            .get_mut(index)
            .ok_or_else(|| RobotIoError::RecipeMismatch {
                reason: format!("no input recipe {index}"),
            })?;
        slot.package.clear();
        slot.recipe.encode_values(values, &mut slot.package)?;
        slot.dirty = true;
        drop(inputs);
        self.shared.inputs_ready.notify_one();
        Ok(())
    }

    /// Closes the connection and stops reconnecting.
    pub async fn close(self) {
        self.supervisor.abort();
        // Let the aborted tasks unwind (closing the socket) before returning.
        tokio::task::yield_now().await;
        lock(&self.shared.status).state = LinkState::Closed;
    }
}

impl Drop for RtdeClient {
    fn drop(&mut self) {
        self.supervisor.abort();
    }
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
    {
        let mut inputs = lock(&shared.inputs);
        for slot in inputs.iter_mut().filter(|s| s.dirty) {
            scratch.extend_from_slice(&slot.package);
            slot.dirty = false;
        }
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
    for slot in lock(&shared.inputs).iter_mut() {
        slot.dirty = !slot.package.is_empty();
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
                lock(&shared.status).state = LinkState::Closed;
                return;
            }
            Ended::Lost(reason) => reason,
        };
        let want_streaming = shared.streaming.load(Ordering::Acquire);
        tracing::warn!("rtde link lost ({reason}); reconnecting");
        if !shared.cfg.reconnect {
            let mut s = lock(&shared.status);
            s.state = LinkState::Closed;
            s.closed_reason = Arc::from(format!("link lost ({reason}), reconnecting disabled"));
            drop(s);
            shared.data_ready.notify_waiters();
            return;
        }
        lock(&shared.status).state = LinkState::Reconnecting;
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
                    let mut s = lock(&shared.status);
                    s.state = LinkState::Closed;
                    s.closed_reason = Arc::from(e.to_string());
                    drop(s);
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
        s.state = LinkState::Up;
        s.epoch = epoch;
        s.controller_version = conn.version;
        drop(s);
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
    {
        let mut slots = lock(&shared.inputs);
        for (slot, new) in slots.iter_mut().zip(inputs) {
            if new.slots() != slot.recipe.slots() {
                return Err(RobotIoError::RecipeMismatch {
                    reason: "the controller answered other input types after reconnecting".into(),
                });
            }
            // The controller may hand out another id: re-encode pending packages with it.
            if new.id() != slot.recipe.id() {
                if let Some(b) = slot.package.get_mut(3) {
                    *b = new.id();
                }
                slot.recipe = new;
            }
        }
    }
    if want_streaming {
        start_stream(&mut conn, shared.cfg.reply_timeout).await?;
    }
    Ok(conn)
}
