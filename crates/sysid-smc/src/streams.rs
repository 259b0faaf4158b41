//! Independent random streams derived from one seed.
//!
//! Parallel work is cut into fixed pieces (particle chunks, Monte Carlo runs, chains);
//! piece `k` draws from `stream(seed, k)`, whatever thread runs it, so results do not
//! depend on the number of threads.

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;

/// The generator used throughout sysid.
pub type Rng = Xoshiro256PlusPlus;

/// SplitMix64's increment (the golden-ratio gamma).
pub(crate) const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function: a bijection of `u64` that mixes every bit.
#[inline(always)]
pub(crate) fn splitmix_finaliser(x: u64) -> u64 {
    let z = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    let z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(GOLDEN_GAMMA);
    splitmix_finaliser(*state)
}

/// The seed every command and Python function uses unless given one.
pub const DEFAULT_SEED: u64 = 1;

/// The generator of piece `stream` of the work seeded by `seed`.
///
/// The 256-bit state is four SplitMix64 outputs of a state that mixes both numbers,
/// so neighbouring seeds and streams give unrelated generators.
///
/// # Example
/// ```
/// use rand::RngExt;
/// let a: f64 = sysid_smc::stream(7, 0).random();
/// let b: f64 = sysid_smc::stream(7, 1).random();
/// assert_ne!(a, b);
/// ```
pub fn stream(seed: u64, stream: u64) -> Rng {
    let mut state = seed;
    let mixed = splitmix64(&mut state) ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03);
    let mut state = mixed;
    let mut bytes = [0u8; 32];
    for chunk in bytes.chunks_exact_mut(8) {
        chunk.copy_from_slice(&splitmix64(&mut state).to_le_bytes());
    }
    Xoshiro256PlusPlus::from_seed(bytes)
}
