//! `hrc-adapt record` and `hrc-adapt emulate` (issue 3).

use std::fs::File;
use std::io::BufWriter;
use std::net::IpAddr;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use crate::Error;
use crate::error::ResultExt as _;
use clap::Args;
use robot_io::client::{ClientConfig, RtdeClient};
use robot_io::emulator::{Emulator, EmulatorConfig, ReplayMode, SimBackend, TraceBackend};
use robot_io::rtde_robot::STATE_FIELDS;
use robot_io::sim::{SimConfig, SimRobot};
use robot_io::trace::{Trace, TraceWriter, WriteOptions};

/// Arguments of `hrc-adapt record`.
#[derive(Debug, Args)]
pub struct RecordArgs {
    /// Controller host (a UR5e, URSim, or the emulator).
    #[arg(long)]
    robot: String,
    /// RTDE port.
    #[arg(long, default_value_t = 30004)]
    port: u16,
    /// Output CSV (UR record.py format: space-separated, vectors as name_0 … name_5).
    #[arg(long)]
    out: PathBuf,
    /// Output frequency [Hz], at most 500 (125 on CB3).
    #[arg(long, default_value_t = 500.0)]
    hz: f64,
    /// RTDE output fields (comma-separated or repeated); default: the robot state fields.
    #[arg(long, value_delimiter = ',', num_args = 1..)]
    fields: Vec<String>,
    /// Floor of the link-loss timeout [ms] (the link is lost after 3 periods without data,
    /// but not sooner than this).
    #[arg(long, default_value_t = 100)]
    link_timeout_ms: u64,
    /// How to record: `native` (our RTDE client: any fields, every package) or `ur_rtde` (SDU
    /// ur_rtde 1.6.5's receive interface, a build with `--features ur-rtde`: the robot state
    /// fields only, on UR's port 30004; ur_rtde keeps only its newest sample, so record polls
    /// it every 0.25 ms and counts each sample it missed).
    #[arg(long, default_value = "native", value_parser = ["native", "ur_rtde"])]
    robot_backend: String,
}

/// Arguments of `hrc-adapt emulate`.
#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("backend").required(true).args(["sim", "trace"])))]
pub struct EmulateArgs {
    /// Back the emulator with the in-process UR5e model (executes our control program's
    /// register protocol).
    #[arg(long)]
    sim: bool,
    /// Back the emulator with a recorded trace (record.py, ur_rtde or RAD CSV).
    #[arg(long, value_name = "CSV")]
    trace: Option<PathBuf>,
    /// Interpolate the trace between rows instead of holding each row.
    #[arg(long, requires = "trace")]
    interpolate: bool,
    /// Address to bind.
    #[arg(long, default_value = "127.0.0.1")]
    bind: IpAddr,
    /// RTDE port.
    #[arg(long, default_value_t = 30004)]
    rtde_port: u16,
    /// Dashboard port.
    #[arg(long, default_value_t = 29999)]
    dashboard_port: u16,
    /// Secondary interface (script) port.
    #[arg(long, default_value_t = 30002)]
    secondary_port: u16,
    /// Real-time interface (script) port.
    #[arg(long, default_value_t = 30003)]
    realtime_port: u16,
    /// Controller cycles per 2 ms of wall time (1 = real time), 1..=100: one cycle every
    /// 2 ms / N of wall time, so far beyond 100 the emulator cannot keep up. (With --sim,
    /// SIGUSR1 injects a protective stop: fault injection for hardware-in-the-loop tests.)
    #[arg(long, default_value_t = 1, value_parser = crate::trial::speedup_parser())]
    speedup: u32,
    /// SCHED_FIFO priority of the emulator's clock thread, as a controller's real-time clock
    /// (0 = normal scheduling, the default), 0..=99. Refused by the OS (no CAP_SYS_NICE or
    /// RLIMIT_RTPRIO), it runs at normal priority and a warning says so.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=99))]
    clock_priority: u8,
    /// SCHED_FIFO priority of the threads that serve RTDE, dashboard and script clients
    /// (0 = normal scheduling, the default), 0..=99; refused, as --clock-priority.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=99))]
    io_priority: u8,
}

fn runtime() -> crate::Result<tokio::runtime::Runtime> {
    crate::trial::rtde_runtime(None).map(|(rt, _)| rt)
}

/// Runs `hrc-adapt record`: records the controller over RTDE into a CSV trace until Ctrl-C.
pub fn record(args: RecordArgs) -> crate::Result<()> {
    if args.robot_backend == "ur_rtde" {
        return record_ur_rtde(&args);
    }
    runtime()?.block_on(record_async(args))
}

/// `record --robot-backend ur_rtde`: the checks that hold in every build, then the recording.
fn record_ur_rtde(args: &RecordArgs) -> crate::Result<()> {
    if args.port != 30004 {
        return Err(Error::usage(
            "--port",
            format!(
                "--port {}: ur_rtde always connects to the controller's RTDE port 30004",
                args.port
            ),
        ));
    }
    let default = STATE_FIELDS
        .iter()
        .all(|f| args.fields.iter().any(|g| g == f))
        && args.fields.len() == STATE_FIELDS.len();
    if !args.fields.is_empty() && !default {
        return Err(Error::usage(
            "--fields",
            format!(
                "--robot-backend ur_rtde records the robot state fields ({}); record other \
                 fields with --robot-backend native",
                STATE_FIELDS.join(",")
            ),
        ));
    }
    if !(args.hz.is_finite() && args.hz > 0.0 && args.hz <= 500.0) {
        return Err(Error::usage(
            "--hz",
            format!("--hz {}: give a frequency in (0, 500] Hz", args.hz),
        ));
    }
    #[cfg(feature = "ur-rtde")]
    {
        record_with_ur_rtde(args)
    }
    #[cfg(not(feature = "ur-rtde"))]
    {
        Err(crate::trial::no_ur_rtde_feature())
    }
}

/// Records through ur_rtde's `RTDEReceiveInterface` until Ctrl-C.
///
/// ur_rtde receives on its own thread and keeps only the newest sample. This loop polls it
/// every 0.25 ms (an eighth of the 500 Hz period) and writes each sample with a new
/// controller timestamp once. A sample that ur_rtde replaced before the poll saw it is lost:
/// the gap in the controller timestamps counts it, and the count is printed at the end.
#[cfg(feature = "ur-rtde")]
fn record_with_ur_rtde(args: &RecordArgs) -> crate::Result<()> {
    use robot_io::trace::{STATE_FIELD_NAMES, state_to_row};
    use robot_io::{RobotState, UrRtdeConfig, UrRtdeReceiver};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    let mut cfg = UrRtdeConfig::new(args.robot.clone());
    cfg.frequency_hz = args.hz;
    let mut rx = UrRtdeReceiver::connect(&cfg)
        .with_context(|| format!("connecting ur_rtde to {}:30004", args.robot))?;
    // The first sample at once: ur_rtde returns from its constructor with the stream's first
    // package and replaces it 2 ms later, before the file is set up.
    let mut state = RobotState::default();
    rx.read(&mut state)
        .context("the first sample from ur_rtde")?;
    let file = File::create(&args.out).map_err(Error::io("create", &args.out))?;
    let mut writer = TraceWriter::new(
        BufWriter::new(file),
        &STATE_FIELD_NAMES,
        &WriteOptions::record_py(),
    )?;
    writer.flush()?;
    let stop = Arc::new(AtomicBool::new(false));
    crate::trial::install_ctrl_c(stop.clone());
    tracing::info!(
        "recording the robot state through ur_rtde at {} Hz to {}; Ctrl-C to stop",
        args.hz,
        args.out.display()
    );
    let period_s = 1.0 / args.hz;
    let mut row = [0.0; 44];
    let mut last_t: Option<f64> = None;
    let mut lost = 0u64;
    let mut last_flush = Instant::now();
    let mut fresh = true; // `state` holds a sample not yet written
    while !stop.load(Ordering::Relaxed) {
        if !fresh {
            match rx.read(&mut state) {
                Ok(()) => {}
                Err(e @ robot_io::RobotIoError::LinkDown { .. }) => {
                    writer.flush()?;
                    tracing::warn!("{e}; reconnecting in 0.5 s");
                    std::thread::sleep(Duration::from_millis(500));
                    if let Err(e) = rx.reconnect() {
                        tracing::warn!("ur_rtde reconnect: {e}");
                    }
                    continue;
                }
                Err(e) => {
                    // No consistent sample this poll; the next poll tries again, and a
                    // sample it misses is counted below.
                    tracing::warn!("{e}");
                    std::thread::sleep(Duration::from_micros(250));
                    continue;
                }
            }
        }
        fresh = false;
        if last_t != Some(state.timestamp_s) {
            if let Some(t0) = last_t {
                let steps = ((state.timestamp_s - t0) / period_s).round();
                if steps > 1.0 {
                    lost += (steps - 1.0) as u64;
                }
            }
            last_t = Some(state.timestamp_s);
            state_to_row(&state, &mut row);
            writer.write_row(&row)?;
        }
        if last_flush.elapsed() >= Duration::from_millis(100) {
            writer.flush()?;
            last_flush = Instant::now();
        }
        std::thread::sleep(Duration::from_micros(250));
    }
    writer.flush()?;
    tracing::info!(
        "wrote {} rows to {} ({lost} samples replaced by ur_rtde before a poll saw them)",
        writer.rows_written(),
        args.out.display()
    );
    Ok(())
}

async fn record_async(args: RecordArgs) -> crate::Result<()> {
    let fields: Vec<String> = if args.fields.is_empty() {
        STATE_FIELDS.iter().map(|s| (*s).to_owned()).collect()
    } else {
        args.fields.clone()
    };
    if fields.first().map(String::as_str) != Some("timestamp")
        && !fields.iter().any(|f| f == "timestamp")
    {
        return Err(Error::usage(
            "--fields",
            "--fields must include timestamp (record.py files start with it)",
        ));
    }
    // timestamp first, as record.py writes it.
    let mut ordered = vec!["timestamp".to_owned()];
    ordered.extend(fields.into_iter().filter(|f| f != "timestamp"));
    let names: Vec<&str> = ordered.iter().map(String::as_str).collect();
    let mut cfg = ClientConfig::new(args.robot.clone(), &names);
    cfg.port = args.port;
    cfg.frequency_hz = args.hz;
    cfg.link_loss_min = Duration::from_millis(args.link_timeout_ms);
    let mut client = RtdeClient::connect(cfg)
        .await
        .with_context(|| format!("connecting to {}:{}", args.robot, args.port))?;
    let v = client.controller_version();
    tracing::info!(
        "connected to controller {}.{}.{}.{}",
        v.major,
        v.minor,
        v.bugfix,
        v.build
    );

    // Columns: vectors expanded as name_0 … name_k.
    let recipe = client.output_recipe().clone();
    let mut columns = Vec::new();
    for (name, slot) in recipe.names().iter().zip(recipe.slots()) {
        if slot.ty.width() == 1 {
            columns.push(name.clone());
        } else {
            columns.extend((0..slot.ty.width()).map(|i| format!("{name}_{i}")));
        }
    }
    let file = File::create(&args.out).map_err(Error::io("create", &args.out))?;
    let mut writer = TraceWriter::new(BufWriter::new(file), &columns, &WriteOptions::record_py())?;
    writer.flush()?;
    let mut buf = client.output_buffer();
    let mut row = vec![0.0; columns.len()];
    let mut values = vec![robot_io::codec::Value::Double(0.0); recipe.len()];
    client.start().await.context("starting the rtde stream")?;
    tracing::info!(
        "recording {} fields at {} Hz to {}; Ctrl-C to stop",
        recipe.len(),
        args.hz,
        args.out.display()
    );

    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    let mut last_flush = Instant::now();
    let mut dropped = 0u64;
    loop {
        tokio::select! {
            r = &mut ctrl_c => {
                r.map_err(|source| Error::Thread { name: "Ctrl-C handler", source })?;
                break;
            }
            r = client.recv_timeout(&mut buf, Duration::from_secs(5)) => {
                let info = match r {
                    Ok(info) => info,
                    Err(e @ robot_io::RobotIoError::Timeout { .. }) => {
                        tracing::warn!("{e}; still waiting (link: {:?})", client.link_state());
                        continue;
                    }
                    Err(e) => return Err(e).context("receiving"),
                };
                dropped += info.dropped;
                buf.decode_into(&mut values)?;
                let mut i = 0;
                for v in &values {
                    for c in 0..v.field_type().width() {
                        if let Some(slot) = row.get_mut(i) {
                            *slot = v.component(c).unwrap_or(f64::NAN);
                        }
                        i += 1;
                    }
                }
                writer.write_row(&row)?;
                if last_flush.elapsed() >= Duration::from_millis(100) {
                    writer.flush()?;
                    last_flush = Instant::now();
                }
            }
        }
    }
    writer.flush()?;
    tracing::info!(
        "wrote {} rows to {} ({} samples dropped by a slow writer, {} reconnects)",
        writer.rows_written(),
        args.out.display(),
        dropped,
        client.reconnects()
    );
    client.close().await;
    Ok(())
}

/// Runs `hrc-adapt emulate`: serves the controller emulator until Ctrl-C.
pub fn emulate(args: EmulateArgs) -> crate::Result<()> {
    let io = robot_io::realtime::RtPriority::new(args.io_priority).ok();
    crate::trial::rtde_runtime(io)?
        .0
        .block_on(emulate_async(args))
}

async fn emulate_async(args: EmulateArgs) -> crate::Result<()> {
    let cfg = EmulatorConfig {
        bind: args.bind,
        rtde_port: args.rtde_port,
        dashboard_port: args.dashboard_port,
        secondary_port: args.secondary_port,
        realtime_port: args.realtime_port,
        speedup: args.speedup,
        clock_priority: robot_io::realtime::RtPriority::new(args.clock_priority).ok(),
        ..EmulatorConfig::default()
    };
    let backend: Box<dyn robot_io::EmulatorBackend> = match (&args.trace, args.sim) {
        (Some(path), false) => {
            let trace = Trace::read(path).map_err(|e| Error::from(e).in_file(path))?;
            let report = trace.report();
            tracing::info!("trace {}: {} rows, {report:?}", path.display(), trace.len());
            let mode = if args.interpolate {
                ReplayMode::Interpolate
            } else {
                ReplayMode::Hold
            };
            Box::new(TraceBackend::new(trace, mode)?)
        }
        (None, true) => Box::new(SimBackend::new(SimRobot::new(SimConfig::ur5e())?)),
        _ => {
            return Err(Error::usage(
                "--sim, --trace",
                "give exactly one of --sim and --trace",
            ));
        }
    };
    let emu = Emulator::start(cfg, backend).await?;
    eprintln!(
        "emulating a UR controller: rtde {}, dashboard {}, script {} and {}; Ctrl-C to stop",
        emu.rtde_addr(),
        emu.dashboard_addr(),
        emu.secondary_addr(),
        emu.realtime_addr()
    );
    // Fault injection for hardware-in-the-loop tests: SIGUSR1 puts the simulated arm into a
    // protective stop, as a collision would (--sim only; release it with the dashboard's
    // `unlock protective stop`).
    let mut usr1 = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::user_defined1())
        .map_err(|source| Error::Thread {
            name: "SIGUSR1 handler",
            source,
        })?;
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    loop {
        tokio::select! {
            r = &mut ctrl_c => {
                r.map_err(|source| Error::Thread { name: "Ctrl-C handler", source })?;
                break;
            }
            _ = usr1.recv() => {
                let done = emu.with_sim(|b| b.robot_mut().inject_protective_stop());
                eprintln!(
                    "emulator: SIGUSR1: {}",
                    if done.is_some() {
                        "protective stop injected (simulated fault)"
                    } else {
                        "ignored: a trace backend cannot be protective-stopped"
                    }
                );
            }
        }
    }
    drop(emu);
    Ok(())
}
