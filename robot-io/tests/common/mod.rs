//! Shared by the emulator's integration tests: an emulator on ephemeral loopback ports with a
//! SIMULATED arm, and a raw RTDE client that sends and receives whole packages (decoded, or as
//! kind byte + payload for what `ControllerPackage` does not decode, such as protocol
//! version 1's packages). Each test binary uses a part of it.
#![allow(dead_code)]

use std::time::Duration;

use robot_io::codec::{ClientPackage, ControllerPackage};
use robot_io::emulator::{Emulator, EmulatorConfig, SimBackend};
use robot_io::sim::{SimConfig, SimRobot};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// Every test body runs under this bound.
pub(crate) const TEST_TIMEOUT: Duration = Duration::from_secs(60);
/// Generous bound on one reply.
pub(crate) const REPLY_TIMEOUT: Duration = Duration::from_secs(10);

/// The emulator at `cfg` with a SimRobot at the UR5e defaults (call inside a tokio runtime).
pub(crate) async fn sim_emulator(cfg: EmulatorConfig) -> Emulator {
    let robot = SimRobot::new(SimConfig::ur5e()).unwrap();
    Emulator::start(cfg, Box::new(SimBackend::new(robot)))
        .await
        .unwrap()
}

/// A raw RTDE connection: one package out, one package in.
pub(crate) struct Raw {
    stream: TcpStream,
    /// The last package received, header included.
    buf: Vec<u8>,
}

impl Raw {
    pub(crate) async fn connect(emu: &Emulator) -> Raw {
        let stream = TcpStream::connect(emu.rtde_addr()).await.unwrap();
        stream.set_nodelay(true).unwrap();
        Raw {
            stream,
            buf: Vec::new(),
        }
    }

    pub(crate) async fn send(&mut self, pkg: ClientPackage<'_>) {
        let mut out = Vec::new();
        pkg.encode(&mut out).unwrap();
        self.stream.write_all(&out).await.unwrap();
    }

    /// Sends a package of type `kind` with `payload` as it is (any protocol version).
    pub(crate) async fn send_raw(&mut self, kind: u8, payload: &[u8]) {
        let mut out = u16::try_from(3 + payload.len())
            .unwrap()
            .to_be_bytes()
            .to_vec();
        out.push(kind);
        out.extend_from_slice(payload);
        self.stream.write_all(&out).await.unwrap();
    }

    /// Reads the next package into the buffer (header: u16 big-endian size including the
    /// header, then the u8 type).
    async fn read_package(&mut self) {
        let mut size = [0u8; 2];
        tokio::time::timeout(REPLY_TIMEOUT, self.stream.read_exact(&mut size))
            .await
            .expect("no reply")
            .unwrap();
        let n = usize::from(u16::from_be_bytes(size));
        assert!(n >= 3, "package size {n} below the header length");
        self.buf.clear();
        self.buf.extend_from_slice(&size);
        self.buf.resize(n, 0);
        tokio::time::timeout(REPLY_TIMEOUT, self.stream.read_exact(&mut self.buf[2..]))
            .await
            .expect("truncated package")
            .unwrap();
    }

    /// The next package from the controller, decoded.
    pub(crate) async fn recv(&mut self) -> ControllerPackage<'_> {
        self.read_package().await;
        ControllerPackage::decode(&self.buf).unwrap()
    }

    /// The next package from the controller as (type byte, payload).
    pub(crate) async fn recv_frame(&mut self) -> (u8, Vec<u8>) {
        self.read_package().await;
        (self.buf[2], self.buf[3..].to_vec())
    }

    /// The payload of the next package of type `kind`, skipping text messages (`M`).
    pub(crate) async fn recv_kind(&mut self, kind: u8) -> Vec<u8> {
        loop {
            let (k, p) = self.recv_frame().await;
            if k == kind {
                return p;
            }
            assert_eq!(k, b'M', "unexpected package {}", k as char);
        }
    }

    /// The next package that is not a text message, decoded.
    pub(crate) async fn recv_non_text(&mut self) -> ControllerPackage<'_> {
        loop {
            self.read_package().await;
            if self.buf[2] != b'M' {
                return ControllerPackage::decode(&self.buf).unwrap();
            }
        }
    }

    /// Requests protocol version `v`; whether it was accepted.
    pub(crate) async fn version(&mut self, v: u16) -> bool {
        self.send(ClientPackage::RequestProtocolVersion { version: v })
            .await;
        self.recv_kind(b'V').await == [1]
    }

    /// Protocol version 2, which must be accepted.
    pub(crate) async fn handshake(&mut self) {
        self.send(ClientPackage::RequestProtocolVersion { version: 2 })
            .await;
        assert_eq!(
            self.recv().await,
            ControllerPackage::ProtocolVersionAccepted(true)
        );
    }

    /// Sets up outputs; returns the recipe id and the answered types.
    pub(crate) async fn setup_outputs(&mut self, frequency_hz: f64, names: &str) -> (u8, String) {
        self.send(ClientPackage::SetupOutputs {
            frequency_hz,
            names,
        })
        .await;
        match self.recv().await {
            ControllerPackage::SetupOutputsReply { recipe_id, types } => {
                (recipe_id, types.to_owned())
            }
            other => panic!("expected an output setup reply, got {other:?}"),
        }
    }

    /// Sets up inputs; returns the recipe id and the answered types.
    pub(crate) async fn setup_inputs(&mut self, names: &str) -> (u8, String) {
        self.send(ClientPackage::SetupInputs { names }).await;
        match self.recv().await {
            ControllerPackage::SetupInputsReply { recipe_id, types } => {
                (recipe_id, types.to_owned())
            }
            other => panic!("expected an input setup reply, got {other:?}"),
        }
    }
}
