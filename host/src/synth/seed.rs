//! Sub-seeds: every random stream of a haul (rig, look, one fish, one
//! frame's snow, one image row's noise) gets its own `ChaCha8Rng` seeded
//! from the haul seed and the stream's coordinates, so rendering frames in
//! parallel, in any order, gives the same bytes.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Stream tags.
#[derive(Debug, Clone, Copy)]
#[repr(u64)]
pub enum Stream {
    /// The rig.
    Rig = 1,
    /// The haul's look (lights, mesh, noise levels).
    Look = 2,
    /// Fish arrivals.
    Arrivals = 3,
    /// One fish (index = arrival number).
    Fish = 4,
    /// Debris arrivals and blobs.
    Debris = 5,
    /// One frame's marine snow.
    Snow = 6,
    /// One image row's sensor noise.
    Noise = 7,
    /// Per-frame strobe gain and mesh drift.
    Frame = 8,
}

fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A 64-bit seed for stream `s` at coordinates `a`, `b` of haul `seed`.
pub fn sub_seed(seed: u64, s: Stream, a: u64, b: u64) -> u64 {
    let mut h = splitmix(seed);
    h = splitmix(h ^ s as u64);
    h = splitmix(h ^ a);
    splitmix(h ^ b.rotate_left(17))
}

/// A generator for stream `s` at `a`, `b`.
pub fn rng(seed: u64, s: Stream, a: u64, b: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(sub_seed(seed, s, a, b))
}

/// A standard normal sample (Box–Muller).
pub fn normal<R: rand::Rng>(rng: &mut R) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A Poisson sample with mean `lambda` (Knuth; `lambda` is small here).
pub fn poisson<R: rand::Rng>(rng: &mut R, lambda: f64) -> u32 {
    if lambda <= 0.0 {
        return 0;
    }
    let l = (-lambda).exp();
    let mut k = 0;
    let mut p = 1.0;
    loop {
        p *= rng.random::<f64>();
        if p <= l || k >= 1000 {
            return k;
        }
        k += 1;
    }
}

/// A hash of integer lattice coordinates to `[0, 1)`, for value noise.
pub fn lattice(seed: u64, x: i64, y: i64) -> f32 {
    let h = splitmix(seed ^ splitmix(x as u64 ^ splitmix(y as u64)));
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Smooth value noise in `[0, 1]` at `(x, y)` (lattice spacing 1).
pub fn value_noise(seed: u64, x: f32, y: f32) -> f32 {
    let (fx, fy) = (x.floor(), y.floor());
    let (ix, iy) = (fx as i64, fy as i64);
    let (tx, ty) = (x - fx, y - fy);
    let sx = tx * tx * (3.0 - 2.0 * tx);
    let sy = ty * ty * (3.0 - 2.0 * ty);
    let a = lattice(seed, ix, iy);
    let b = lattice(seed, ix + 1, iy);
    let c = lattice(seed, ix, iy + 1);
    let d = lattice(seed, ix + 1, iy + 1);
    let top = a + (b - a) * sx;
    let bot = c + (d - c) * sx;
    top + (bot - top) * sy
}
