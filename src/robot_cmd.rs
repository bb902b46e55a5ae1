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
    runtime()?.block_on(record_async(args))
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
