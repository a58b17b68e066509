//! The device's behaviour, independent of the serial port: answer
//! commands, drive the strobe scheduler on the simulated board, process
//! frames, and produce reports.

use std::rc::Rc;

use fishtrack_core::link::{
    Command, Counters, DeviceError, ErrorCode, FishClosed, FrameEdges, FrameReport, Report, Status,
};
use fishtrack_core::strobe::{Line, Schedule, StrobeConfig, StrobePins};

use crate::hw::{self, PinFaults, SharedBoard, SimPin};

/// Faults the simulator can inject (`--fault`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Fault {
    /// Each frame's edges fire up to 1.5 ms late (an overloaded interrupt).
    Jitter,
    /// The LED lights 300 µs after the exposure has started.
    LateStrobe,
    /// The LED cuts out half-way through the exposure.
    ShortStrobe,
    /// The right camera misses the trigger pulse in every 5th frame.
    DroppedTrigger,
    /// Corrupt bytes on the serial line between reports.
    Garbage,
}

/// Worst per-frame latency of [`Fault::Jitter`], µs.
pub const JITTER_MAX_US: u64 = 1_500;
/// How late [`Fault::LateStrobe`] lights, after the exposure start, µs.
pub const LATE_STROBE_US: u64 = 300;

/// What happens to each triggered frame: the device's image pipeline.
///
/// The core vision pipeline (segmentation → stereo pairing → length →
/// tracking, `fishtrack-core`) runs behind it in
/// `crate::pipeline_frames::PipelineFrames`.
pub trait FrameProcessor {
    /// Process frame `index` of the sequence; `None` when there is no such
    /// frame (no haul, or the haul is exhausted).
    fn process_frame(&mut self, index: u32) -> Option<FrameOutcome>;
}

/// The result of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameOutcome {
    /// Counts for the frame.
    pub report: FrameReport,
    /// Fish whose tracks closed at this frame.
    pub closed: Vec<FishClosed>,
}

/// No camera frames (timing bench only).
pub struct NoFrames;

impl FrameProcessor for NoFrames {
    fn process_frame(&mut self, _index: u32) -> Option<FrameOutcome> {
        None
    }
}

enum Mode {
    Idle,
    Free(Schedule),
    Bench(Schedule, u32),
}

/// The simulated housing processor.
pub struct Device {
    board: SharedBoard,
    pins: StrobePins<SimPin, SimPin, SimPin>,
    config: StrobeConfig,
    mode: Mode,
    fault: Option<Fault>,
    rng: u64,
    counters: Counters,
    processor: Box<dyn FrameProcessor>,
}

impl Device {
    /// A device at power-up with the default timing.
    pub fn new(fault: Option<Fault>, processor: Box<dyn FrameProcessor>) -> Self {
        let board: SharedBoard = Rc::default();
        let pins = hw::pins(&board);
        let mut d = Device {
            board,
            pins,
            config: StrobeConfig::default(),
            mode: Mode::Idle,
            fault,
            rng: 0x9E37_79B9_7F4A_7C15,
            counters: Counters::default(),
            processor,
        };
        d.apply_faults();
        d
    }

    /// Simulated monotonic clock, µs.
    pub fn now_us(&self) -> u64 {
        self.board.borrow().now_us
    }

    /// Move the simulated clock forward to `us` (never back): `--realtime`
    /// keeps it on the wall clock while idle.
    pub fn advance_clock_to(&mut self, us: u64) {
        let mut b = self.board.borrow_mut();
        b.now_us = b.now_us.max(us);
    }

    /// Counters (rx/tx are kept by the caller through [`Device::counters_mut`]).
    pub fn counters_mut(&mut self) -> &mut Counters {
        &mut self.counters
    }

    /// `true` while frames are being triggered.
    pub fn running(&self) -> bool {
        !matches!(self.mode, Mode::Idle)
    }

    /// A pseudo-random number (xorshift64*), for faults.
    pub fn random(&mut self) -> u64 {
        let mut x = self.rng;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.rng = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn apply_faults(&mut self) {
        let c = self.config;
        let faults = match self.fault {
            Some(Fault::LateStrobe) => PinFaults {
                strobe_rise_delay_us: u64::from(c.strobe_lead_us) + LATE_STROBE_US,
                ..PinFaults::default()
            },
            Some(Fault::ShortStrobe) => PinFaults {
                strobe_max_on_us: Some(u64::from(c.strobe_lead_us) + u64::from(c.exposure_us / 2)),
                ..PinFaults::default()
            },
            _ => PinFaults::default(),
        };
        self.board.borrow_mut().faults = faults;
    }

    fn status(&self) -> Report {
        Report::Status(Status {
            running: self.running(),
            config: self.config,
            frames: self.counters.frames,
            uptime_us: self.now_us(),
        })
    }

    fn schedule(&self, frames: Option<u32>) -> Option<Schedule> {
        // Arm 1 ms from now.
        let start = self.now_us() + 1_000;
        match frames {
            Some(n) => Schedule::with_frames(self.config, start, n).ok(),
            None => Schedule::new(self.config, start).ok(),
        }
    }

    /// Answer one command.
    pub fn handle(&mut self, cmd: Command) -> Vec<Report> {
        match cmd {
            Command::Configure(c) => {
                if self.running() {
                    return vec![busy()];
                }
                match c.validate() {
                    Ok(()) => {
                        self.config = c;
                        self.apply_faults();
                        vec![self.status()]
                    }
                    Err(e) => vec![Report::Error(DeviceError::new(
                        ErrorCode::BadConfig,
                        &e.to_string(),
                    ))],
                }
            }
            Command::Start => {
                if self.running() {
                    return vec![busy()];
                }
                if let Some(s) = self.schedule(None) {
                    self.mode = Mode::Free(s);
                }
                vec![self.status()]
            }
            Command::Stop => {
                self.mode = Mode::Idle;
                let _ = self.pins.all_low();
                self.board.borrow_mut().log.clear();
                vec![self.status()]
            }
            Command::Status => vec![self.status()],
            Command::Counters => vec![Report::Counters(self.counters)],
            Command::RunBench { frames } => {
                if self.running() {
                    return vec![busy()];
                }
                if frames == 0 {
                    return vec![Report::BenchDone { frames: 0 }];
                }
                if let Some(s) = self.schedule(Some(frames)) {
                    self.mode = Mode::Bench(s, frames);
                }
                Vec::new()
            }
        }
    }

    /// Run one frame if running; returns its reports. `wait_until` is called
    /// with the time of each edge before it is driven (`--realtime` sleeps
    /// there; otherwise simulated time just jumps).
    pub fn step(&mut self, mut wait_until: impl FnMut(u64)) -> Vec<Report> {
        let mut schedule = match std::mem::replace(&mut self.mode, Mode::Idle) {
            Mode::Idle => return Vec::new(),
            Mode::Free(s) => (s, None),
            Mode::Bench(s, n) => (s, Some(n)),
        };
        let frame = schedule.0.frame();
        let latency = match self.fault {
            Some(Fault::Jitter) => self.random() % (JITTER_MAX_US + 1),
            _ => 0,
        };
        self.board.borrow_mut().faults.drop_right_trigger =
            self.fault == Some(Fault::DroppedTrigger) && frame % 5 == 2;
        while let Some(edge) = schedule.0.next_edge().filter(|e| e.frame == frame) {
            let at = (edge.at_us + latency).max(self.now_us());
            wait_until(at);
            self.board.borrow_mut().now_us = at;
            match schedule.0.poll(at, &mut self.pins) {
                Ok(Some(_)) => {
                    self.counters.edges = self.counters.edges.saturating_add(1);
                    if latency > 0 {
                        self.counters.late_edges = self.counters.late_edges.saturating_add(1);
                    }
                }
                Ok(None) => break,
                Err(e) => {
                    return vec![Report::Error(DeviceError::new(
                        ErrorCode::Pin,
                        &e.to_string(),
                    ))];
                }
            }
        }
        self.counters.frames = self.counters.frames.saturating_add(1);
        let recorded = self.board.borrow_mut().take_edges();
        let mut reports = vec![Report::Edges(frame_edges(frame, &recorded))];
        if let Some(out) = self.processor.process_frame(frame) {
            self.counters.frames_processed = self.counters.frames_processed.saturating_add(1);
            reports.push(Report::Frame(out.report));
            reports.extend(out.closed.into_iter().map(Report::FishClosed));
        }
        self.mode = match schedule {
            (s, None) => Mode::Free(s),
            (s, Some(n)) if !s.finished() => Mode::Bench(s, n),
            (_, Some(n)) => {
                reports.push(Report::BenchDone { frames: n });
                Mode::Idle
            }
        };
        reports
    }
}

fn busy() -> Report {
    Report::Error(DeviceError::new(ErrorCode::Busy, "stop the cameras first"))
}

/// Collect the recorded edges of one frame.
pub fn frame_edges(frame: u32, recorded: &[hw::Recorded]) -> FrameEdges {
    let mut e = FrameEdges {
        frame,
        ..FrameEdges::default()
    };
    for &(line, high, t) in recorded {
        let slot = match (line, high) {
            (Line::TriggerLeft, true) => &mut e.trigger_left_rise,
            (Line::TriggerLeft, false) => &mut e.trigger_left_fall,
            (Line::TriggerRight, true) => &mut e.trigger_right_rise,
            (Line::TriggerRight, false) => &mut e.trigger_right_fall,
            (Line::Strobe, true) => &mut e.strobe_rise,
            (Line::Strobe, false) => &mut e.strobe_fall,
        };
        *slot = Some(t);
    }
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bench(fault: Option<Fault>, frames: u32) -> Vec<Report> {
        let mut d = Device::new(fault, Box::new(NoFrames));
        assert!(d.handle(Command::RunBench { frames }).is_empty());
        let mut out = Vec::new();
        while d.running() {
            out.extend(d.step(|_| {}));
        }
        out
    }

    fn edges(reports: &[Report]) -> Vec<FrameEdges> {
        reports
            .iter()
            .filter_map(|r| match r {
                Report::Edges(e) => Some(*e),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn healthy_bench_reports_exact_edges() {
        let r = bench(None, 3);
        assert_eq!(r.last(), Some(&Report::BenchDone { frames: 3 }));
        let e = edges(&r);
        assert_eq!(e.len(), 3);
        for (n, f) in e.iter().enumerate() {
            let t0 = 1_000 + 200_000 * n as u64;
            assert_eq!(f.frame, n as u32);
            assert_eq!(f.strobe_rise, Some(t0));
            assert_eq!(f.trigger_left_rise, Some(t0 + 500));
            assert_eq!(f.trigger_right_rise, Some(t0 + 500));
            assert_eq!(f.trigger_left_fall, Some(t0 + 600));
            assert_eq!(f.strobe_fall, Some(t0 + 3_000));
        }
    }

    #[test]
    fn faults_show_in_the_edges() {
        let late = edges(&bench(Some(Fault::LateStrobe), 2));
        assert_eq!(late[0].strobe_rise, Some(1_000 + 500 + LATE_STROBE_US));
        let short = edges(&bench(Some(Fault::ShortStrobe), 2));
        assert_eq!(short[1].strobe_fall, Some(201_000 + 500 + 1_000));
        let dropped = edges(&bench(Some(Fault::DroppedTrigger), 6));
        let missing: Vec<u32> = dropped
            .iter()
            .filter(|e| e.trigger_right_rise.is_none())
            .map(|e| e.frame)
            .collect();
        assert_eq!(missing, vec![2]);
        let jit = edges(&bench(Some(Fault::Jitter), 20));
        assert!(jit
            .iter()
            .any(|e| e.trigger_left_rise != Some(1_500 + 200_000 * u64::from(e.frame))));
    }

    #[test]
    fn bad_config_and_busy_are_errors() {
        let mut d = Device::new(None, Box::new(NoFrames));
        let bad = StrobeConfig {
            strobe_width_us: 1,
            ..StrobeConfig::default()
        };
        assert!(matches!(
            d.handle(Command::Configure(bad))[..],
            [Report::Error(DeviceError {
                code: ErrorCode::BadConfig,
                ..
            })]
        ));
        d.handle(Command::Start);
        assert!(matches!(
            d.handle(Command::RunBench { frames: 2 })[..],
            [Report::Error(DeviceError {
                code: ErrorCode::Busy,
                ..
            })]
        ));
        d.step(|_| {});
        d.handle(Command::Stop);
        assert!(!d.running());
    }
}
