//! The truth rearranged frame by frame, with the paper's detectability rule.
//!
//! A fish counts in a frame ("countable") when its visible area in the left
//! view is at least θ_A^L, the segmentation's lower area limit (eq. 4,
//! Table I: 2000 px at 2048², scaled by `Params::for_frame`): below it a
//! segmenter is *meant* to drop the object, so a prediction on it is
//! neither rewarded nor punished.

use fishtrack_core::Params;

use crate::error::InputError;
use crate::truth::{Truth, TruthFrame};

/// A truth fish as seen in one frame.
#[derive(Debug, Clone, Copy)]
pub struct TruthObject<'a> {
    /// Index of the fish in `truth.fish`.
    pub fish: usize,
    /// The fish's id.
    pub id: i64,
    /// Its record for this frame.
    pub at: &'a TruthFrame,
    /// Visible left area ≥ θ_A^L (and a left box exists).
    pub countable: bool,
}

impl TruthObject<'_> {
    /// The left box (`None` when the fish is visible only in the right view).
    pub fn left_box(&self) -> Option<[f64; 4]> {
        self.at.left_box
    }
}

/// Truth objects per frame (index `frame − 1`), fish in truth order.
#[derive(Debug, Clone)]
pub struct TruthFrames<'a> {
    /// The truth.
    pub truth: &'a Truth,
    /// θ_A^L used, pixels.
    pub area_min: f64,
    /// Per frame, the fish present in it (either view).
    pub frames: Vec<Vec<TruthObject<'a>>>,
}

impl<'a> TruthFrames<'a> {
    /// Arranges `truth` by frame; θ_A^L = `Params::for_frame(truth.width).area_min`.
    pub fn new(truth: &'a Truth) -> Result<Self, InputError> {
        let area_min = Params::for_frame(truth.width).area_min as f64;
        Self::with_area_min(truth, area_min)
    }

    /// As [`TruthFrames::new`] with an explicit θ_A^L.
    pub fn with_area_min(truth: &'a Truth, area_min: f64) -> Result<Self, InputError> {
        let mut frames: Vec<Vec<TruthObject<'a>>> = vec![Vec::new(); truth.frames as usize];
        for (k, fish) in truth.fish.iter().enumerate() {
            for at in &fish.frames {
                if at.frame < 1 || at.frame > truth.frames {
                    return Err(InputError::plain(
                        format!("truth.json: fish {} frame {}", fish.id, at.frame),
                        format!("frame outside 1..={}", truth.frames),
                    ));
                }
                let slot = &mut frames[at.frame as usize - 1];
                if slot.iter().any(|o| o.fish == k) {
                    return Err(InputError::plain(
                        format!("truth.json: fish {} frame {}", fish.id, at.frame),
                        "frame listed twice",
                    ));
                }
                slot.push(TruthObject {
                    fish: k,
                    id: fish.id as i64,
                    at,
                    countable: at.left_box.is_some() && at.left_area >= area_min,
                });
            }
        }
        Ok(TruthFrames {
            truth,
            area_min,
            frames,
        })
    }

    /// The objects of frame `f` (1-based); empty outside the haul.
    pub fn at(&self, f: u32) -> &[TruthObject<'a>] {
        f.checked_sub(1)
            .and_then(|i| self.frames.get(i as usize))
            .map_or(&[], |v| v.as_slice())
    }

    /// Objects of frame `f` that have a left box, with those boxes.
    pub fn left_objects(&self, f: u32) -> (Vec<TruthObject<'a>>, Vec<[f64; 4]>) {
        self.at(f)
            .iter()
            .filter_map(|o| o.left_box().map(|b| (*o, b)))
            .unzip()
    }

    /// Fish (indices) with at least one countable frame: the paper's
    /// "correctly detected" population of eq. (16).
    pub fn countable_fish(&self) -> Vec<usize> {
        let mut v: Vec<usize> = self
            .frames
            .iter()
            .flatten()
            .filter(|o| o.countable)
            .map(|o| o.fish)
            .collect();
        v.sort_unstable();
        v.dedup();
        v
    }
}
