//! The vision system's imperfections: classifier doubt and depth noise, drawn per row from a
//! generator seeded by (scenario seed, step, UAV, row), so that rows render in any order, on
//! any number of threads, to the same bits; and, with `camera.depth_ray = "random"`, the
//! point of each pixel whose ray its depth is measured along ([`RowRayPoints`]), from a
//! generator of its own, so that the centre-ray frames keep their bits.

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// 2^32, the span of a half draw.
const TWO_POW_32: f64 = 4_294_967_296.0;

/// The noise of one row of one frame.
pub struct RowNoise {
    rng: ChaCha8Rng,
    unknown_fraction: f64,
    w_lo: f64,
    w_span: f64,
}

/// One pixel's draw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelNoise {
    /// Whether the classifier doubts the pixel (it becomes U).
    pub doubt: bool,
    /// Multiplicative depth error `w`, in `[w_lo, w_hi]`.
    pub w: f64,
}

impl RowNoise {
    /// The generator of row `row` of UAV `uav`'s frame at `step`.
    pub fn new(
        seed: u64,
        step: u64,
        uav: u32,
        row: u32,
        unknown_fraction: f64,
        noise: [f64; 2],
    ) -> Self {
        RowNoise {
            rng: row_generator(seed ^ 0x5EED_F1EE_7C0D_E000, step, uav, row),
            unknown_fraction,
            w_lo: noise[0],
            w_span: noise[1] - noise[0],
        }
    }

    /// The next pixel's draw; every pixel draws one `u64`, whatever its label: its high half
    /// decides the doubt, its low half the depth error (2^-32 resolution is plenty, and one
    /// draw per pixel halves the generator's share of a frame).
    pub fn next_pixel(&mut self) -> PixelNoise {
        let bits = self.rng.next_u64();
        let unit = |half: u64| half as f64 / TWO_POW_32;
        let doubt = unit(bits >> 32) < self.unknown_fraction;
        let w = self.w_lo + self.w_span * unit(bits & 0xFFFF_FFFF);
        PixelNoise { doubt, w }
    }
}

/// The random points of one row's pixels through which their depth rays pass.
pub struct RowRayPoints {
    rng: ChaCha8Rng,
}

impl RowRayPoints {
    /// The generator of row `row` of UAV `uav`'s frame at `step`.
    pub fn new(seed: u64, step: u64, uav: u32, row: u32) -> Self {
        RowRayPoints {
            rng: row_generator(seed ^ 0xDE97_4A11_0F5E_7000, step, uav, row),
        }
    }

    /// The next pixel's point `(du, dv)`, each uniform in `[0, 1)`: the depth ray passes
    /// through image point `(c + du, r + dv)`, inside pixel `(r, c)`.
    pub fn next_point(&mut self) -> (f64, f64) {
        let bits = self.rng.next_u64();
        (
            (bits >> 32) as f64 / TWO_POW_32,
            (bits & 0xFFFF_FFFF) as f64 / TWO_POW_32,
        )
    }
}

/// A generator seeded by `(base, step, uav, row)`.
fn row_generator(base: u64, step: u64, uav: u32, row: u32) -> ChaCha8Rng {
    let mut h = splitmix(base);
    for part in [step, uav as u64, row as u64] {
        h = splitmix(h ^ part);
    }
    ChaCha8Rng::seed_from_u64(h)
}

fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
