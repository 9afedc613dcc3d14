//! Numbers for people: times in the unit that fits them (µs, ms or s, as hyperfine
//! prints them), one unit per table column, and other values to the digits that mean
//! something. Pure formatting; what a number means is the caller's.

/// A unit of time a table prints in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeUnit {
    Micro,
    Milli,
    Second,
}

impl TimeUnit {
    /// The unit that prints `seconds` with its digits before the decimal point: µs
    /// under a millisecond, ms under a second, else s.
    pub fn fitting(seconds: f64) -> TimeUnit {
        match seconds.abs() {
            s if s < 1e-3 => TimeUnit::Micro,
            s if s < 1.0 => TimeUnit::Milli,
            _ => TimeUnit::Second,
        }
    }

    /// One unit for a column of times: the one that fits its smallest finite value, so
    /// that no value of the column prints as zero (seconds when it has none).
    pub fn for_column(seconds: impl IntoIterator<Item = f64>) -> TimeUnit {
        seconds
            .into_iter()
            .filter(|s| s.is_finite())
            .map(f64::abs)
            .reduce(f64::min)
            .map_or(TimeUnit::Second, TimeUnit::fitting)
    }

    pub fn symbol(self) -> &'static str {
        match self {
            TimeUnit::Micro => "µs",
            TimeUnit::Milli => "ms",
            TimeUnit::Second => "s",
        }
    }

    /// `seconds` in this unit without the symbol: three decimals in seconds, one in ms
    /// and µs (hyperfine's digits); a dash when not finite.
    pub fn number(self, seconds: f64) -> String {
        if !seconds.is_finite() {
            return "—".to_owned();
        }
        match self {
            TimeUnit::Micro => format!("{:.1}", seconds * 1e6),
            TimeUnit::Milli => format!("{:.1}", seconds * 1e3),
            TimeUnit::Second => format!("{seconds:.3}"),
        }
    }

    /// `seconds` in this unit with its symbol: `45.0 µs`.
    pub fn format(self, seconds: f64) -> String {
        match seconds.is_finite() {
            true => format!("{} {}", self.number(seconds), self.symbol()),
            false => "—".to_owned(),
        }
    }

    /// A range in this unit, the symbol once: `7.4–8.9 ms`.
    pub fn range(self, [low, high]: [f64; 2]) -> String {
        match low.is_finite() && high.is_finite() {
            true => format!(
                "{}–{} {}",
                self.number(low),
                self.number(high),
                self.symbol()
            ),
            false => "—".to_owned(),
        }
    }
}

/// `seconds` in the unit that fits it: `45.0 µs`, `7.5 ms`, `2.488 s`.
pub fn duration(seconds: f64) -> String {
    TimeUnit::fitting(seconds).format(seconds)
}

/// `value` to `digits` significant digits, without trailing zeros (`0.02264`, `2`,
/// `20000`); an exponent below 1e-4 and from 1e6 on (`1.5e-7`); a dash when not finite.
pub fn significant(value: f64, digits: usize) -> String {
    if !value.is_finite() {
        return "—".to_owned();
    }
    if value == 0.0 {
        return "0".to_owned();
    }
    let magnitude = value.abs().log10().floor() as i32;
    if !(-4..6).contains(&magnitude) {
        let text = format!("{:.*e}", digits.saturating_sub(1), value);
        let (mantissa, exponent) = text.split_once('e').expect("an exponent");
        return format!("{}e{exponent}", trim_zeros(mantissa));
    }
    let decimals = (digits as i32 - 1 - magnitude).max(0) as usize;
    trim_zeros(&format!("{value:.decimals$}")).to_owned()
}

/// `text` without the zeros that end its fraction (and the point, if nothing is left).
fn trim_zeros(text: &str) -> &str {
    match text.contains('.') {
        true => text.trim_end_matches('0').trim_end_matches('.'),
        false => text,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_print_in_the_unit_that_fits_them() {
        assert_eq!(duration(45e-6), "45.0 µs");
        assert_eq!(duration(0.0075), "7.5 ms");
        assert_eq!(duration(0.5337), "533.7 ms");
        assert_eq!(duration(2.48789), "2.488 s");
        assert_eq!(duration(f64::NAN), "—");
    }

    #[test]
    fn a_column_takes_the_unit_of_its_smallest_time() {
        let unit = TimeUnit::for_column([0.3, 45e-6, f64::NAN, 0.002]);
        assert_eq!(unit, TimeUnit::Micro);
        assert_eq!(unit.format(0.3), "300000.0 µs");
        assert_eq!(unit.format(45e-6), "45.0 µs");
        assert_eq!(TimeUnit::for_column([]), TimeUnit::Second);
        assert_eq!(TimeUnit::Milli.range([0.0074, 0.0089]), "7.4–8.9 ms");
    }

    #[test]
    fn numbers_keep_their_meaningful_digits() {
        assert_eq!(significant(0.02264154330493038, 4), "0.02264");
        assert_eq!(significant(0.1, 4), "0.1");
        assert_eq!(significant(2.0, 4), "2");
        assert_eq!(significant(20000.0, 4), "20000");
        assert_eq!(significant(1e-4, 4), "0.0001");
        assert_eq!(significant(1.5e-7, 4), "1.5e-7");
        assert_eq!(significant(-0.3, 4), "-0.3");
        assert_eq!(significant(f64::NAN, 4), "—");
    }
}
