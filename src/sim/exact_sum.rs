//! Exact sums of floating-point numbers, whatever their order: whole-system figures
//! (energy, momentum) come out bit for bit the same however the disks are stored or
//! divided among threads and ranks.
//!
//! An [`ExactSum`] holds the sum as a fixed-point number wide enough for every finite
//! `f64` (a "small superaccumulator", after R. M. Neal, arXiv:1505.05571): 67 signed
//! chunks of 32 bits, from 2⁻¹⁰⁷⁴ up. Adding a number adds its 53-bit significand into
//! the three chunks it spans, so the held sum is exact, and exact sums of the same
//! numbers are equal in any order and in any grouping ([`ExactSum::merge`]). Only
//! [`ExactSum::value`] rounds, once, to the nearest `f64`.

/// Chunks of 32 bits from 2⁻¹⁰⁷⁴: the highest significand bit of the largest finite
/// `f64` is bit 2,097, in chunk 65; one chunk more takes the carries of long sums.
const CHUNKS: usize = 67;

/// Additions a chunk takes before its carries must be pushed up: each adds at most 2⁵³
/// in size to an `i64`, which holds 2⁶³.
const ADDS_BEFORE_CARRY: u32 = 256;

/// The exact sum of the `f64`s added to it.
#[derive(Clone, Debug, PartialEq)]
pub struct ExactSum {
    chunks: [i64; CHUNKS],
    /// Additions since the carries were last pushed up.
    pending: u32,
    /// The sum of the non-finite numbers added (infinities and NaN): 0 when none was.
    non_finite: f64,
}

impl Default for ExactSum {
    fn default() -> ExactSum {
        ExactSum {
            chunks: [0; CHUNKS],
            pending: 0,
            non_finite: 0.0,
        }
    }
}

/// Values of [`ExactSum::to_words`]: the chunks and the non-finite sum.
pub const EXACT_SUM_WORDS: usize = CHUNKS + 1;

impl ExactSum {
    /// Adds `value` exactly.
    #[inline]
    pub fn add(&mut self, value: f64) {
        let bits = value.to_bits();
        let exponent = ((bits >> 52) & 0x7ff) as usize;
        if exponent == 0x7ff {
            self.non_finite += value;
            return;
        }
        // value = ±significand · 2^(lowest − 1074); subnormals share the lowest exponent.
        let normal = usize::from(exponent != 0);
        let significand = (bits & ((1 << 52) - 1)) | ((normal as u64) << 52);
        let lowest = exponent - normal;
        let (first, shift) = (lowest / 32, lowest % 32);
        // The significand shifted into place spans two chunks: its low 32 bits in the
        // first (the shift may drop bits above them, which the second takes), the rest
        // (at most 53 bits) in the second.
        let low = ((significand << shift) & 0xffff_ffff) as i64;
        let high = (significand >> (32 - shift)) as i64;
        // 0 for a positive value, −1 for a negative one: x ^ sign − sign is then ±x.
        let sign = -((bits >> 63) as i64);
        self.chunks[first] += (low ^ sign) - sign;
        self.chunks[first + 1] += (high ^ sign) - sign;
        self.pending += 1;
        if self.pending == ADDS_BEFORE_CARRY {
            self.carry();
        }
    }

    /// Adds every sum of `other` into this one.
    pub fn merge(&mut self, other: &ExactSum) {
        self.carry();
        let mut other = other.clone();
        other.carry();
        for (chunk, add) in self.chunks.iter_mut().zip(other.chunks) {
            *chunk += add;
        }
        self.pending = 1;
        self.non_finite += other.non_finite;
    }

    /// Pushes each chunk's carry into the next, leaving every chunk but the last in
    /// [0, 2³²) and the sign in the last.
    fn carry(&mut self) {
        for idx in 0..CHUNKS - 1 {
            let carry = self.chunks[idx] >> 32;
            self.chunks[idx] -= carry << 32;
            self.chunks[idx + 1] += carry;
        }
        self.pending = 0;
    }

    /// The sum rounded to the nearest `f64` (ties to even); infinite when it is beyond
    /// the largest `f64`, NaN or infinite when a non-finite number was added.
    pub fn value(&self) -> f64 {
        if self.non_finite != 0.0 {
            return self.non_finite;
        }
        let mut sum = self.clone();
        sum.carry();
        let negative = sum.chunks[CHUNKS - 1] < 0;
        if negative {
            for chunk in &mut sum.chunks {
                *chunk = -*chunk;
            }
            sum.carry();
        }
        let Some(top) = sum.chunks.iter().rposition(|&chunk| chunk != 0) else {
            return 0.0;
        };
        // The top three chunks hold at least 65 significant bits: one more bit below
        // them, set when any lower chunk is not zero, makes the conversion round as the
        // exact sum would.
        let low = top.saturating_sub(2);
        let mut head: u128 = 0;
        for idx in (low..=top).rev() {
            head = (head << 32) | sum.chunks[idx] as u128;
        }
        let head = (head << 1) | u128::from(sum.chunks[..low].iter().any(|&c| c != 0));
        let magnitude = scale_by_power_of_two(head as f64, 32 * low as i32 - 1075);
        if negative { -magnitude } else { magnitude }
    }

    /// The sum as [`EXACT_SUM_WORDS`] `f64`s, each exact (chunks below 2³²), to send
    /// between ranks; [`ExactSum::from_words`] reads them back.
    pub fn to_words(&self) -> Vec<f64> {
        let mut sum = self.clone();
        sum.carry();
        let mut words: Vec<f64> = sum.chunks.iter().map(|&chunk| chunk as f64).collect();
        words.push(sum.non_finite);
        words
    }

    pub fn from_words(words: &[f64]) -> ExactSum {
        let mut chunks = [0; CHUNKS];
        for (chunk, &word) in chunks.iter_mut().zip(words) {
            *chunk = word as i64;
        }
        ExactSum {
            chunks,
            pending: 1,
            non_finite: words[CHUNKS],
        }
    }
}

impl FromIterator<f64> for ExactSum {
    fn from_iter<I: IntoIterator<Item = f64>>(values: I) -> ExactSum {
        let mut sum = ExactSum::default();
        for value in values {
            sum.add(value);
        }
        sum
    }
}

/// `value` · 2^`exponent`, in steps that neither overflow nor underflow on the way
/// (only the last step rounds, and only into the subnormals).
fn scale_by_power_of_two(mut value: f64, mut exponent: i32) -> f64 {
    let step = |e: i32| f64::from_bits(((e + 1023) as u64) << 52);
    while exponent > 1000 {
        value *= step(1000);
        exponent -= 1000;
    }
    while exponent < -1000 {
        value *= step(-1000);
        exponent += 1000;
    }
    value * step(exponent)
}

#[cfg(test)]
mod tests {
    use rand::seq::SliceRandom;
    use rand::{RngExt, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    use super::*;

    fn exact(values: &[f64]) -> f64 {
        values.iter().copied().collect::<ExactSum>().value()
    }

    #[test]
    fn a_sum_is_exact_where_a_running_sum_loses_everything() {
        assert_eq!(exact(&[1e308, 1.0, -1e308]), 1.0);
        assert_eq!(exact(&[1.0, 1e-300, -1.0]), 1e-300);
        assert_eq!(exact(&[f64::MAX, f64::MAX]), f64::INFINITY);
        assert_eq!(exact(&[-f64::MAX, -f64::MAX, f64::MAX]), -f64::MAX);
        assert_eq!(exact(&[5e-324, 5e-324]), 1e-323);
        assert_eq!(exact(&[]), 0.0);
        assert_eq!(exact(&[-2.5, 1.0]), -1.5);
    }

    #[test]
    fn the_value_is_the_exact_sum_rounded_to_nearest_even() {
        // 2⁵³ + 1 is a tie between 2⁵³ and 2⁵³ + 2: the even one wins; a bit more below
        // breaks the tie upwards.
        let two_53 = 9_007_199_254_740_992.0;
        assert_eq!(exact(&[two_53, 1.0]), two_53);
        assert_eq!(exact(&[two_53, 1.0, 1e-30]), two_53 + 2.0);
        assert_eq!(exact(&[two_53, 3.0]), two_53 + 4.0);
        assert_eq!(exact(&[-two_53, -1.0, -1e-30]), -two_53 - 2.0);
    }

    #[test]
    fn integers_sum_as_integers() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        let values: Vec<i64> = (0..10_000)
            .map(|_| rng.random_range(-(1 << 40)..(1 << 40)))
            .collect();
        let floats: Vec<f64> = values.iter().map(|&v| v as f64).collect();
        assert_eq!(exact(&floats), values.iter().sum::<i64>() as f64);
    }

    #[test]
    fn any_order_and_any_grouping_give_the_same_bits() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let mut values: Vec<f64> = (0..5_000)
            .map(|_| {
                let magnitude = 10f64.powi(rng.random_range(-300..300));
                rng.random_range(-1.0..1.0) * magnitude
            })
            .collect();
        let reference = exact(&values);
        for _ in 0..5 {
            values.shuffle(&mut rng);
            assert_eq!(exact(&values).to_bits(), reference.to_bits());
            let cut = rng.random_range(0..values.len());
            let (left, right) = values.split_at(cut);
            let mut merged: ExactSum = left.iter().copied().collect();
            let sent = right.iter().copied().collect::<ExactSum>().to_words();
            merged.merge(&ExactSum::from_words(&sent));
            assert_eq!(merged.value().to_bits(), reference.to_bits());
        }
    }

    #[test]
    fn a_plain_sum_of_like_numbers_is_within_rounding_of_the_exact_one() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let values: Vec<f64> = (0..100_000).map(|_| rng.random_range(0.0..2.0)).collect();
        let plain: f64 = values.iter().sum();
        assert!((exact(&values) - plain).abs() <= 1e-10 * plain);
    }

    #[test]
    fn non_finite_numbers_give_what_a_plain_sum_gives() {
        assert_eq!(exact(&[1.0, f64::INFINITY]), f64::INFINITY);
        assert!(exact(&[f64::INFINITY, f64::NEG_INFINITY]).is_nan());
        assert!(exact(&[1.0, f64::NAN]).is_nan());
    }

    #[test]
    fn pushing_the_carries_up_keeps_the_sum() {
        let big = f64::from_bits(0x433f_ffff_ffff_ffff); // 2⁵⁴ − 2: every significand bit set
        let mut sum = ExactSum::default();
        for _ in 0..1000 {
            sum.add(big);
            sum.add(-0.5 * big);
        }
        let before = sum.value();
        sum.carry();
        assert!(
            sum.chunks[..CHUNKS - 1]
                .iter()
                .all(|&c| (0..1 << 32).contains(&c))
        );
        assert_eq!(sum.value(), before);
        assert_eq!(before, 500.0 * big);
    }
}
