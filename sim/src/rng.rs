//! Seeds for random sources: each source's seed is derived from the scenario seed and the source's
//! name (DESIGN.md §2), so adding a sensor does not change the noise of the others.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// FNV-1a hash of a name (64 bit): stable across platforms and Rust versions.
pub fn fnv1a64(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3))
}

/// SplitMix64 finaliser: spreads the bits of a 64-bit value.
pub fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Seed of the random source `name` under the scenario seed.
pub fn derive_seed(scenario_seed: u64, name: &str) -> u64 {
    splitmix64(scenario_seed ^ splitmix64(fnv1a64(name)))
}

/// A reproducible generator for the random source `name`.
pub fn source_rng(scenario_seed: u64, name: &str) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(derive_seed(scenario_seed, name))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_differ_by_name_and_by_scenario_seed_and_are_stable() {
        assert_ne!(derive_seed(1, "a"), derive_seed(1, "b"));
        assert_ne!(derive_seed(1, "a"), derive_seed(2, "a"));
        assert_eq!(derive_seed(42, "iso/laser_p1"), derive_seed(42, "iso/laser_p1"));
        // FNV-1a of "a" (published test vector).
        assert_eq!(fnv1a64("a"), 0xaf63_dc4c_8601_ec8c);
    }
}
