//! `fishtrack-firmware-sim`: the Cam-trawl's in-housing processor simulated
//! on the host.
//!
//! A simulated monotonic clock, three output pins (left/right camera
//! trigger, LED strobe) that record every edge with its time, the core's
//! strobe scheduler ([`fishtrack_core::strobe`]) driving them, and the
//! core's serial protocol ([`fishtrack_core::link`]) on a real serial port.
//! Frames run at the configured rate in *simulated* time (no 200 ms sleeps)
//! unless `--realtime` is given. `--fault` injects the faults the bench
//! check must catch (the smoltcp `FaultInjector` model).

mod device;
mod hw;
mod pipeline_frames;

use std::io::{ErrorKind, Read, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use fishtrack_core::link::{self, Command, Decoder, DeviceError, ErrorCode, Report, MAX_FRAME};

use device::{Device, Fault, FrameProcessor, NoFrames};
use pipeline_frames::PipelineFrames;

#[derive(Parser)]
#[command(
    name = "fishtrack-firmware-sim",
    version,
    about = "Simulated Cam-trawl housing processor: strobe/camera timing and serial link"
)]
struct Cli {
    /// Serial port to serve (e.g. one end of a pseudo-terminal pair).
    #[arg(long)]
    serial: PathBuf,
    /// Haul directory whose frames (DIR/left/*) are processed per trigger.
    #[arg(long)]
    haul: Option<PathBuf>,
    /// Inject a fault.
    #[arg(long, value_enum)]
    fault: Option<Fault>,
    /// Pace frames in wall-clock time instead of simulated time.
    #[arg(long)]
    realtime: bool,
    /// Baud rate (ignored by pseudo-terminals).
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
}

struct Link {
    port: Box<dyn serialport::SerialPort>,
    garbage: bool,
}

impl Link {
    fn send(&mut self, dev: &mut Device, report: &Report) -> anyhow::Result<()> {
        if self.garbage && dev.random() % 3 == 0 {
            // 1–24 random bytes (zeros included) between two frames.
            let n = 1 + (dev.random() % 24) as usize;
            let junk: Vec<u8> = (0..n).map(|_| dev.random() as u8).collect();
            self.port.write_all(&junk)?;
        }
        let mut buf = [0u8; MAX_FRAME];
        let n = link::encode(report, &mut buf).context("encoding a report")?;
        self.port.write_all(&buf[..n])?;
        let c = dev.counters_mut();
        c.tx_frames = c.tx_frames.saturating_add(1);
        Ok(())
    }
}

fn serve(cli: Cli) -> anyhow::Result<()> {
    let processor: Box<dyn FrameProcessor> = match &cli.haul {
        Some(dir) => {
            let h = PipelineFrames::open(dir)?;
            eprintln!(
                "fishtrack-firmware-sim: haul {} with {} frames through the core pipeline",
                h.dir().display(),
                h.len()
            );
            Box::new(h)
        }
        None => Box::new(NoFrames),
    };
    let port = serialport::new(cli.serial.to_string_lossy(), cli.baud)
        .timeout(Duration::from_millis(50))
        .open()
        .with_context(|| format!("{}: cannot open serial port", cli.serial.display()))?;
    eprintln!(
        "fishtrack-firmware-sim: serving {} (protocol {}, fault: {})",
        cli.serial.display(),
        link::PROTOCOL_VERSION,
        cli.fault
            .and_then(|f| clap::ValueEnum::to_possible_value(&f))
            .map(|v| v.get_name().to_string())
            .unwrap_or_else(|| "none".into())
    );
    let mut dev = Device::new(cli.fault, processor);
    let mut link = Link {
        port,
        garbage: cli.fault == Some(Fault::Garbage),
    };
    let mut decoder = Decoder::new();
    let mut rx = [0u8; 256];
    let wall0 = Instant::now();
    let realtime = cli.realtime;
    loop {
        if realtime {
            dev.advance_clock_to(u64::try_from(wall0.elapsed().as_micros()).unwrap_or(u64::MAX));
        }
        let timeout = if dev.running() { 1 } else { 50 };
        link.port.set_timeout(Duration::from_millis(timeout))?;
        match link.port.read(&mut rx) {
            Ok(0) => {}
            Ok(n) => {
                for &b in &rx[..n] {
                    let reports = match decoder.push::<Command>(b) {
                        None => continue,
                        Some(Ok(cmd)) => {
                            let c = dev.counters_mut();
                            c.rx_frames = c.rx_frames.saturating_add(1);
                            dev.handle(cmd)
                        }
                        Some(Err(e)) => {
                            let c = dev.counters_mut();
                            c.rx_errors = c.rx_errors.saturating_add(1);
                            vec![Report::Error(DeviceError::new(
                                ErrorCode::BadFrame,
                                &e.to_string(),
                            ))]
                        }
                    };
                    for r in &reports {
                        link.send(&mut dev, r)?;
                    }
                }
            }
            Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::Interrupted => {}
            Err(e) => {
                eprintln!("fishtrack-firmware-sim: serial line closed ({e}); exiting");
                return Ok(());
            }
        }
        let reports = dev.step(|t_us| {
            if realtime {
                let due = wall0 + Duration::from_micros(t_us);
                if let Some(d) = due.checked_duration_since(Instant::now()) {
                    std::thread::sleep(d);
                }
            }
        });
        for r in &reports {
            link.send(&mut dev, r)?;
        }
        link.port.flush()?;
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match serve(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("fishtrack-firmware-sim: error: {e:#}");
            ExitCode::from(1)
        }
    }
}
