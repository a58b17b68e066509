//! Synthetic Cam-trawl hauls with ground truth (`fishtrack synth`).
//!
//! There is no public labelled Cam-trawl data, so FishTrack makes its own,
//! hard in the ways the paper describes (Sections I–II, V): 5 fps, fish
//! that jump hundreds of pixels between frames and live about four frames
//! in view, low contrast under uneven LED light, dim caudal fins, marine
//! snow, debris, a drifting trawl mesh, and crossing fish that occlude
//! each other.
//!
//! Data flows one way: [`SynthConfig`] → [`Haul::plan`] (rig, look, every
//! fish's and blob's life, all from sub-seeds of the haul seed) →
//! [`render::render_view`] per frame and camera (independent, so frames
//! render in parallel and the bytes do not depend on the order) →
//! [`output`] (PNG frames, `calibration.yml`, `truth.json`, atomically).
//!
//! Modules: [`rig`] (cameras, distortion), [`fish`] (shape, motion),
//! [`scene`] (light, mesh, debris, snow), [`render`], [`output`] (files and
//! truth), [`yaml`] (OpenCV FileStorage), [`hardness`] (nearest-neighbour
//! association on the truth, paper eq. 16), [`montage`].

pub mod fish;
pub mod hardness;
pub mod montage;
pub mod output;
pub mod render;
pub mod rig;
pub mod scene;
pub mod seed;
pub mod yaml;

use crate::error::InputError;

use rand::Rng;

use fish::{FishLife, School};
use render::CamGrid;
use rig::{Cam, Rig};
use scene::{Debris, Look, MeshFrame};
use seed::{poisson, rng, Stream};

pub use output::write_haul;

/// Frames per second of the Cam-trawl (paper Section II).
pub const FPS: f64 = 5.0;
/// Mean number of fish arriving together (a school); arrivals of schools
/// are Poisson with mean `fish_rate / MEAN_SCHOOL` per frame, so
/// `fish_rate` stays the mean number of fish entering per frame.
const MEAN_SCHOOL: f64 = 2.0;
/// Frames simulated before frame 1 so the view starts populated.
const WARM_UP: i64 = 10;

/// What to synthesise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthConfig {
    /// Number of stereo frame pairs.
    pub frames: u32,
    /// Seed: the same seed gives the same bytes.
    pub seed: u64,
    /// Frame width and height, pixels.
    pub size: u32,
    /// Mean number of fish entering per frame.
    pub fish_rate: f64,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            frames: 30,
            seed: 1,
            size: 2048,
            fish_rate: 1.0,
        }
    }
}

impl SynthConfig {
    /// Checks the values (bad ones are input errors naming the option).
    pub fn validate(&self) -> Result<(), InputError> {
        if self.frames == 0 || self.frames > 100_000 {
            return Err(InputError::plain(
                "--frames",
                "must be between 1 and 100000",
            ));
        }
        if !(64..=8192).contains(&self.size) {
            return Err(InputError::plain(
                "--size",
                "must be between 64 and 8192 pixels",
            ));
        }
        if !self.fish_rate.is_finite() || !(0.0..=50.0).contains(&self.fish_rate) {
            return Err(InputError::plain(
                "--fish-rate",
                "must be a number between 0 and 50",
            ));
        }
        Ok(())
    }
}

/// A planned haul: everything but the pixels.
#[derive(Debug, Clone)]
pub struct Haul {
    /// The request.
    pub config: SynthConfig,
    /// The stereo rig.
    pub rig: Rig,
    /// Lights, water, mesh and noise.
    pub look: Look,
    /// Every fish that exists during the haul (some are never visible).
    pub fish: Vec<FishLife>,
    /// Body gain of each fish: its contrast over the light at its mean position.
    pub fish_gain: Vec<f64>,
    /// Debris blobs.
    pub debris: Vec<Debris>,
    /// Mesh drift and strobe flicker per frame (index 0 = frame 1).
    pub mesh_frames: Vec<MeshFrame>,
    /// Smooth per-camera fields (left, right).
    pub grids: [CamGrid; 2],
}

impl Haul {
    /// Plans a haul.
    pub fn plan(config: SynthConfig) -> Result<Haul, InputError> {
        config.validate()?;
        let seed = config.seed;
        let rig = Rig::random(&mut rng(seed, Stream::Rig, 0, 0), config.size);
        let look = Look::random(&mut rng(seed, Stream::Look, 0, 0), &rig);
        let mut arrivals = rng(seed, Stream::Arrivals, 0, 0);
        let mut fish = Vec::new();
        for t in (1 - WARM_UP)..=config.frames as i64 {
            for _ in 0..poisson(&mut arrivals, config.fish_rate / MEAN_SCHOOL) {
                let school = School::random(&mut arrivals);
                let members = 1 + poisson(&mut arrivals, MEAN_SCHOOL - 1.0);
                for m in 0..members {
                    let k = fish.len() as u64;
                    let late = i64::from(m > 0 && arrivals.random_bool(0.3));
                    let mut r = rng(seed, Stream::Fish, k, 0);
                    fish.push(FishLife::simulate(&mut r, &rig, &school, t + late));
                }
            }
        }
        let tx = rig.half_fov_tan();
        let ty = 0.5 * rig.height as f64 / rig.left.fy;
        let fish_gain = fish
            .iter()
            .map(|f| {
                let inside: Vec<f64> = f
                    .poses
                    .iter()
                    .filter(|p| {
                        (p.centre.x / p.centre.z).abs() < tx && (p.centre.y / p.centre.z).abs() < ty
                    })
                    .map(|p| look.light(&p.centre))
                    .collect();
                let mean = if inside.is_empty() {
                    f.poses.iter().map(|p| look.light(&p.centre)).sum::<f64>()
                        / f.poses.len().max(1) as f64
                } else {
                    inside.iter().sum::<f64>() / inside.len() as f64
                };
                f.spec.contrast / mean.max(1e-3)
            })
            .collect();
        let debris = scene::simulate_debris(seed, &look, &rig, config.frames);
        let mesh_frames = look.mesh_frames(seed, config.frames);
        let mut grids = [
            CamGrid::new(&rig, &look, Cam::Left),
            CamGrid::new(&rig, &look, Cam::Right),
        ];
        let m = grids[0].max_backscatter().max(grids[1].max_backscatter());
        for g in &mut grids {
            g.normalise_backscatter(m, look.glow_gamma as f32);
        }
        Ok(Haul {
            config,
            rig,
            look,
            fish,
            fish_gain,
            debris,
            mesh_frames,
            grids,
        })
    }
}
