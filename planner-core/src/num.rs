//! Numbers in messages, readable whatever their size.
//!
//! `{}` prints an f64 in full decimal: 1e308 is 309 digits, 1e-300 is 300
//! zeros. A client that sends such a number gets it back in the message
//! that refuses it, so messages print numbers through [`readable`].

use std::fmt;

/// `v` as `{}` prints it while that is short, else in scientific notation
/// (`1e308`, `-2.5e-12`). A precision (`{:.6}`) applies to either form.
pub fn readable(v: f64) -> Readable {
    Readable(v)
}

/// See [`readable`].
#[derive(Clone, Copy, Debug)]
pub struct Readable(pub f64);

impl fmt::Display for Readable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = self.0;
        let a = v.abs();
        let scientific = v.is_finite() && a != 0.0 && !(1e-5..1e16).contains(&a);
        match (scientific, f.precision()) {
            (true, Some(p)) => write!(f, "{v:.p$e}"),
            (true, None) => write!(f, "{v:e}"),
            (false, Some(p)) => write!(f, "{v:.p$}"),
            (false, None) => write!(f, "{v}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::readable;

    #[test]
    fn short_numbers_print_as_usual_and_long_ones_in_scientific_notation() {
        for (v, text) in [
            (60.0, "60"),
            (0.1, "0.1"),
            (-180.5, "-180.5"),
            (0.0, "0"),
            (1e15, "1000000000000000"),
            (0.00001, "0.00001"),
            (1e308, "1e308"),
            (-1e308, "-1e308"),
            (f64::MAX, "1.7976931348623157e308"),
            (1e-300, "1e-300"),
            (2.5e-7, "2.5e-7"),
            (f64::INFINITY, "inf"),
            (f64::NAN, "NaN"),
        ] {
            assert_eq!(readable(v).to_string(), text);
        }
        assert_eq!(format!("{:.6}", readable(5.25)), "5.250000");
        assert_eq!(format!("{:.6}", readable(1e308)), "1.000000e308");
        assert_eq!(format!("{:.1}", readable(-3e-9)), "-3.0e-9");
    }
}
