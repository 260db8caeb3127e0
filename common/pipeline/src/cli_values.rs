//! Value parsers for numeric command-line arguments (clap `value_parser`): NaN, infinities
//! and out-of-range values are refused while the command line is parsed, before any stage
//! starts, and clap's message names the flag.

pub use crate::dataset_args::parse_at_least_one as at_least_one;

fn number<T: std::str::FromStr>(s: &str) -> Result<T, String> {
    s.trim()
        .parse::<T>()
        .map_err(|_| format!("'{s}' is not a number"))
}

/// A finite number (any sign).
pub fn finite(s: &str) -> Result<f64, String> {
    match number::<f64>(s)? {
        v if v.is_finite() => Ok(v),
        _ => Err(format!("'{s}' is not a finite number")),
    }
}

/// A finite number > 0.
pub fn positive(s: &str) -> Result<f64, String> {
    match number::<f64>(s)? {
        v if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("'{s}' must be a finite number > 0")),
    }
}

/// A finite number ≥ 0.
pub fn non_negative(s: &str) -> Result<f64, String> {
    match number::<f64>(s)? {
        v if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("'{s}' must be a finite number ≥ 0")),
    }
}

/// A finite number > 0 that is finite as f32 too.
pub fn positive_f32(s: &str) -> Result<f32, String> {
    let v = positive(s)? as f32;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("'{s}' must be a finite number > 0"))
    }
}

/// A finite number ≥ 0 that is finite as f32 too.
pub fn non_negative_f32(s: &str) -> Result<f32, String> {
    let v = non_negative(s)? as f32;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("'{s}' must be a finite number ≥ 0"))
    }
}

/// A frame rate: frames per second ≥ 0, where 0 means as fast as possible.
pub fn rate(s: &str) -> Result<f64, String> {
    non_negative(s)
        .map_err(|_| format!("'{s}' is not a rate: give frames per second ≥ 0 (0 = no cap)"))
}

/// A whole number ≥ 3 (neighbours of a covariance).
pub fn at_least_three(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if n >= 3 => Ok(n),
        _ => Err(format!("'{s}' is not a whole number of at least 3")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_nan_infinities_and_out_of_range() {
        for bad in ["nan", "NaN", "inf", "-inf", "x", ""] {
            assert!(finite(bad).is_err(), "{bad}");
            assert!(positive(bad).is_err(), "{bad}");
            assert!(non_negative(bad).is_err(), "{bad}");
            assert!(rate(bad).is_err(), "{bad}");
        }
        assert_eq!(finite("-2.5"), Ok(-2.5));
        assert!(positive("0").is_err());
        assert_eq!(positive("0.03"), Ok(0.03));
        assert!(non_negative("-1").is_err());
        assert_eq!(non_negative("0"), Ok(0.0));
        assert!(positive_f32("1e300").is_err());
        assert!(non_negative_f32("1e39").is_err());
        assert_eq!(non_negative_f32("0.01"), Ok(0.01));
        assert!(rate("-1")
            .expect_err("negative")
            .contains("frames per second"));
        assert!(at_least_one("0").is_err());
        assert_eq!(at_least_one("4"), Ok(4));
        assert!(at_least_three("2").is_err());
    }
}
