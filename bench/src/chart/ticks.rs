//! Where axis ticks go and how their labels read.
//!
//! plotters' defaults print `10000.0` and give a log axis one labelled tick
//! per decade (none at all when the data span less than a decade), so the
//! charts choose their own ticks and format them here.

/// A tick label as a person would write it: `10,000`, `0.5`, `1.25`,
/// `-2`, and powers of ten only where plain digits would be unreadable
/// (`3e-5`, `2e15`).
pub fn label(v: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    if v == 0.0 {
        return "0".into();
    }
    let sign = if v < 0.0 { "-" } else { "" };
    let a = v.abs();
    let body = if !(1e-4..1e15).contains(&a) {
        scientific(a)
    } else if a >= 1.0 && (a - a.round()).abs() <= 1e-9 * a {
        // Exact integers print whole, however many digits they have.
        group_thousands(&format!("{}", a.round() as u64))
    } else {
        decimal(a)
    };
    format!("{sign}{body}")
}

/// Six significant digits at most, trailing zeros dropped, so that
/// floating-point noise in computed ticks (0.30000000000000004) vanishes.
fn decimal(a: f64) -> String {
    let magnitude = a.log10().floor() as i32;
    let decimals = (5 - magnitude).max(0) as usize;
    let s = format!("{a:.decimals$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        &s
    };
    match s.split_once('.') {
        Some((int, frac)) => format!("{}.{frac}", group_thousands(int)),
        None => group_thousands(s),
    }
}

/// `3e-5`, `1.5e-5`: the mantissa as short as it can be.
fn scientific(a: f64) -> String {
    let s = format!("{a:.5e}");
    match s.split_once('e') {
        Some((m, e)) => {
            let m = m.trim_end_matches('0').trim_end_matches('.');
            format!("{m}e{e}")
        }
        None => s,
    }
}

/// Commas every three digits from the right of a run of digits.
fn group_thousands(digits: &str) -> String {
    let n = digits.len();
    let mut out = String::with_capacity(n + n / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (n - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// Round ticks on a linear axis over `lo..=hi`: a step of 1, 2 or 5 times a
/// power of ten, the finest that gives at most `max` ticks.
pub fn linear(lo: f64, hi: f64, max: usize) -> Vec<f64> {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    if !(hi > lo) || !lo.is_finite() || !hi.is_finite() {
        return vec![lo];
    }
    let max = max.max(2);
    let rough = (hi - lo) / max as f64;
    let mut power = 10f64.powf(rough.log10().floor());
    loop {
        for m in [1.0, 2.0, 5.0] {
            let step = m * power;
            let ticks = steps(lo, hi, step);
            if ticks.len() <= max {
                return ticks;
            }
        }
        power *= 10.0;
    }
}

/// Every multiple of `step` in `lo..=hi`, each computed from its index so
/// that rounding errors do not accumulate.
fn steps(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// Which multiples of each power of ten may carry a labelled tick, from the
/// densest choice to the sparsest.
const MANTISSAS: [&[f64]; 4] = [
    &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
    &[1.0, 2.0, 5.0],
    &[1.0, 3.0],
    &[1.0],
];

/// Labelled ticks on a log axis over `lo..=hi` (both positive): the densest
/// of 1-2-3..9, 1-2-5, 1-3 or 1 per decade that gives at most `max` ticks;
/// every few powers of ten when even one a decade is too many; and round
/// linear steps when the range is so narrow that no choice gives three.
pub fn log(lo: f64, hi: f64, max: usize) -> Vec<f64> {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    if !(lo > 0.0) || !hi.is_finite() {
        return linear(lo, hi, max);
    }
    let max = max.max(2);
    let chosen = MANTISSAS
        .iter()
        .map(|m| decades(lo, hi, m, 1))
        .find(|t| t.len() <= max);
    let ticks = match chosen {
        Some(t) => t,
        None => {
            let spread = (hi / lo).log10();
            let every = (spread / (max - 1) as f64).ceil().max(1.0) as i32;
            decades(lo, hi, &[1.0], every)
        }
    };
    if ticks.len() < 3 {
        let lin = linear(lo, hi, max);
        if lin.len() > ticks.len() {
            return lin;
        }
    }
    ticks
}

/// Unlabelled grid lines for a log axis: every 1..9 multiple of each power
/// of ten, unless there are so many decades that they would be a smear.
pub fn log_minor(lo: f64, hi: f64) -> Vec<f64> {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    if !(lo > 0.0) || !hi.is_finite() || (hi / lo).log10() > 6.0 {
        return Vec::new();
    }
    decades(lo, hi, MANTISSAS[0], 1)
}

/// `m * 10^e` for each mantissa `m` and every `every`-th exponent `e`,
/// within `lo..=hi`.
fn decades(lo: f64, hi: f64, mantissas: &[f64], every: i32) -> Vec<f64> {
    let first = lo.log10().floor() as i32;
    let last = hi.log10().ceil() as i32;
    let mut out = Vec::new();
    for e in first..=last {
        if e.rem_euclid(every) != 0 {
            continue;
        }
        for m in mantissas {
            // Parse rather than multiply: 3 * 10^-1 must be exactly 0.3.
            let v: f64 = format!("{m}e{e}").parse().unwrap_or(m * 10f64.powi(e));
            if v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9) {
                out.push(v);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_read_like_numbers_people_write() {
        assert_eq!(label(10000.0), "10,000");
        assert_eq!(label(1234567.0), "1,234,567");
        assert_eq!(label(2.0), "2");
        assert_eq!(label(100.0), "100");
        assert_eq!(label(0.5), "0.5");
        assert_eq!(label(1.25), "1.25");
        assert_eq!(label(0.001), "0.001");
        assert_eq!(label(0.0001), "0.0001");
        assert_eq!(label(1e-5), "1e-5");
        assert_eq!(label(3e-5), "3e-5");
        assert_eq!(label(1.5e-5), "1.5e-5");
        assert_eq!(label(2e15), "2e15");
        assert_eq!(label(1234.5), "1,234.5");
        assert_eq!(label(0.1 + 0.2), "0.3");
        assert_eq!(label(0.0), "0");
        assert_eq!(label(-0.0), "0");
        assert_eq!(label(-10000.0), "-10,000");
        assert_eq!(label(-0.25), "-0.25");
        assert_eq!(label(-3e-5), "-3e-5");
    }

    #[test]
    fn linear_ticks_are_round_and_bounded() {
        assert_eq!(linear(0.0, 10.0, 8), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        assert_eq!(linear(1.0, 7.0, 8), vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
        let t = linear(0.0, 0.37, 8);
        assert_eq!(t.len(), 8, "{t:?}");
        assert_eq!(label(t[3]), "0.15");
        let t = linear(-120.0, 940.0, 6);
        assert_eq!(t, vec![0.0, 200.0, 400.0, 600.0, 800.0]);
        assert_eq!(linear(3.0, 3.0, 8), vec![3.0]);
    }

    fn labels(t: &[f64]) -> Vec<String> {
        t.iter().map(|&v| label(v)).collect()
    }

    #[test]
    fn log_ticks_label_several_values_per_range() {
        // Two decades: 1-2-5.
        assert_eq!(
            labels(&log(1.0, 100.0, 8)),
            ["1", "2", "5", "10", "20", "50", "100"]
        );
        // Four decades: 1-2-5 would be 13, 1-3 is 9, so one a decade.
        assert_eq!(
            labels(&log(1.0, 10000.0, 8)),
            ["1", "10", "100", "1,000", "10,000"]
        );
        assert_eq!(labels(&log(1.0, 10000.0, 9)).len(), 9);
        // Less than a decade: every multiple.
        assert_eq!(
            labels(&log(0.011, 0.052, 8)),
            ["0.02", "0.03", "0.04", "0.05"]
        );
        // Too narrow for any power-of-ten multiple to repeat: linear steps.
        let t = log(1.1, 1.9, 8);
        assert!(t.len() >= 3, "{t:?}");
        assert_eq!(labels(&t), ["1.2", "1.4", "1.6", "1.8"]);
        // Fifteen decades: every third power of ten.
        assert_eq!(
            labels(&log(1e-6, 1e9, 8)),
            ["1e-6", "0.001", "1", "1,000", "1,000,000", "1,000,000,000"]
        );
    }

    #[test]
    fn log_ticks_fall_in_range() {
        for (lo, hi) in [(0.8, 1.25e6), (3e-5, 0.2), (0.9, 1.1), (40.0, 45.0)] {
            let t = log(lo, hi, 8);
            assert!(t.len() >= 3 && t.len() <= 8, "{lo}..{hi}: {t:?}");
            assert!(t.iter().all(|&v| v >= lo && v <= hi), "{lo}..{hi}: {t:?}");
        }
        assert_eq!(log_minor(1.0, 10.0).len(), 10);
        assert!(log_minor(1e-9, 1.0).is_empty());
    }
}
