//! Simulated hardware: a monotonic clock and output pins that record every
//! edge with its time, with the physical faults `--fault` can inject.

use std::cell::RefCell;
use std::convert::Infallible;
use std::rc::Rc;

use embedded_hal::digital::{ErrorType, OutputPin};
use fishtrack_core::strobe::{Line, StrobePins};

/// One recorded edge: line, level, time in µs.
pub type Recorded = (Line, bool, u64);

/// Physical faults of the simulated board (applied where the light and the
/// camera inputs are, i.e. when an edge is recorded).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PinFaults {
    /// The LED lights this many µs after its driver is switched on.
    pub strobe_rise_delay_us: u64,
    /// The LED driver cuts out after this many µs on (over-current trip).
    pub strobe_max_on_us: Option<u64>,
    /// The right camera's trigger input misses the current frame's pulse.
    pub drop_right_trigger: bool,
}

/// The board: clock, edge log and faults, shared by the three pins.
#[derive(Debug, Default)]
pub struct Board {
    /// Simulated monotonic clock, µs since power-up.
    pub now_us: u64,
    /// Edges recorded since the last [`Board::take_edges`].
    pub log: Vec<Recorded>,
    /// Injected faults.
    pub faults: PinFaults,
    last_strobe_rise: u64,
}

impl Board {
    fn record(&mut self, line: Line, high: bool) {
        let mut t = self.now_us;
        match (line, high) {
            (Line::Strobe, true) => {
                t += self.faults.strobe_rise_delay_us;
                self.last_strobe_rise = t;
            }
            (Line::Strobe, false) => {
                if let Some(cap) = self.faults.strobe_max_on_us {
                    t = t.min(self.last_strobe_rise + cap);
                }
            }
            (Line::TriggerRight, _) if self.faults.drop_right_trigger => return,
            _ => {}
        }
        self.log.push((line, high, t));
    }

    /// The edges recorded so far, emptying the log.
    pub fn take_edges(&mut self) -> Vec<Recorded> {
        std::mem::take(&mut self.log)
    }
}

/// A board shared by its pins.
pub type SharedBoard = Rc<RefCell<Board>>;

/// An output pin of the simulated board.
#[derive(Debug)]
pub struct SimPin {
    line: Line,
    board: SharedBoard,
}

impl ErrorType for SimPin {
    type Error = Infallible;
}

impl OutputPin for SimPin {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.board.borrow_mut().record(self.line, false);
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Infallible> {
        self.board.borrow_mut().record(self.line, true);
        Ok(())
    }
}

/// The three pins of `board`.
pub fn pins(board: &SharedBoard) -> StrobePins<SimPin, SimPin, SimPin> {
    let pin = |line| SimPin {
        line,
        board: Rc::clone(board),
    };
    StrobePins {
        trigger_left: pin(Line::TriggerLeft),
        trigger_right: pin(Line::TriggerRight),
        strobe: pin(Line::Strobe),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pins_record_time_and_faults() {
        let board: SharedBoard = Rc::default();
        let mut p = pins(&board);
        board.borrow_mut().faults = PinFaults {
            strobe_rise_delay_us: 0,
            strobe_max_on_us: Some(1_000),
            drop_right_trigger: true,
        };
        board.borrow_mut().now_us = 10;
        p.set(Line::Strobe, true).unwrap();
        p.set(Line::TriggerRight, true).unwrap();
        board.borrow_mut().now_us = 5_000;
        p.set(Line::Strobe, false).unwrap();
        assert_eq!(
            board.borrow_mut().take_edges(),
            vec![(Line::Strobe, true, 10), (Line::Strobe, false, 1_010)]
        );
    }
}
