//! C's `%g` (six significant digits), both as text and as a rounding of a
//! number to the value that text would parse back to.

use std::fmt::Write;

/// Appends `x` formatted exactly as C's `printf("%g", x)` prints it.
pub fn fmt_g(x: f64, out: &mut String) {
    if x == 0.0 {
        out.push_str(if x.is_sign_negative() { "-0" } else { "0" });
        return;
    }
    if x.is_nan() {
        out.push_str(if x.is_sign_negative() { "-nan" } else { "nan" });
        return;
    }
    if x.is_infinite() {
        out.push_str(if x < 0.0 { "-inf" } else { "inf" });
        return;
    }
    // %g takes the exponent X of the %e conversion with precision P-1 = 5;
    // it uses %e style when X < -4 or X >= P, fixed style otherwise, and
    // removes trailing zeros either way.
    let e = format!("{x:.5e}");
    let (mant, exp) = e.split_once('e').expect("{:e} always has an exponent");
    let exp: i32 = exp.parse().expect("{:e} exponent is an integer");
    if !(-4..6).contains(&exp) {
        out.push_str(strip_zeros(mant));
        let _ = write!(out, "e{}{:02}", if exp < 0 { '-' } else { '+' }, exp.abs());
    } else {
        let fixed = format!("{:.*}", (5 - exp) as usize, x);
        out.push_str(strip_zeros(&fixed));
    }
}

fn strip_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// Exact powers of ten representable in `f64`.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// `x` rounded to six significant decimal digits: the number that
/// `fmt_g(x)` parses back to. The SPD programs print every number with
/// `%g`, so generating through this rounding makes `spd:NAME:SIZE` hold
/// exactly what the SPD's own NFF output holds.
///
/// Fast path: scale by an exact power of ten so the six digits are the
/// integer part, round to the nearest integer (ties to even, as glibc's
/// printf rounds exact ties), and divide back; the division is one correctly
/// rounded operation, so the result equals parsing the decimal text. The
/// scaled product is itself rounded, so where it sits within an ulp of a
/// half, the exact residual of the product (by fused multiply-add) decides
/// the side. Numbers outside the exact power-of-ten range go through text.
pub fn round_g6(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let a = x.abs();
    // Decimal exponent estimated from the binary one; corrected below.
    let e2 = ((a.to_bits() >> 52) & 0x7ff) as i32 - 1023;
    let mut exp = (e2 as f64 * std::f64::consts::LOG10_2).floor() as i32;
    for _ in 0..3 {
        let k = 5 - exp; // scale so that the mantissa has 6 integer digits
        if k < 0 || k as usize >= POW10.len() {
            break;
        }
        let p = POW10[k as usize];
        let m = a * p;
        if m >= 999_999.5 {
            exp += 1;
            continue;
        }
        if m < 99_999.5 {
            exp -= 1;
            continue;
        }
        // m is positive and below 2^53: truncation is floor (and cheaper
        // than the libm call on baseline x86-64).
        let fl = (m as u64) as f64;
        let f = m - fl; // exact
        let r = if f > 0.5 + 1e-9 {
            fl + 1.0
        } else if f < 0.5 - 1e-9 {
            fl
        } else {
            // The exact product is m + e; its side of the half decides.
            let e = a.mul_add(p, -m);
            let d = (f - 0.5) + e;
            if d > 0.0 || (d == 0.0 && (m as u64) & 1 == 1) {
                fl + 1.0
            } else {
                fl
            }
        };
        return (r / p).copysign(x);
    }
    let mut s = String::with_capacity(16);
    fmt_g(x, &mut s);
    s.parse().expect("%g output parses")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn g(x: f64) -> String {
        let mut s = String::new();
        fmt_g(x, &mut s);
        s
    }

    #[test]
    fn matches_c_printf() {
        assert_eq!(g(0.0), "0");
        assert_eq!(g(-0.0), "-0");
        assert_eq!(g(1.0), "1");
        assert_eq!(g(0.078), "0.078");
        assert_eq!(g(1e-5), "1e-05");
        assert_eq!(g(0.0001), "0.0001");
        assert_eq!(g(123456.0), "123456");
        assert_eq!(g(1234567.0), "1.23457e+06");
        assert_eq!(g(100000.0), "100000");
        assert_eq!(g(999999.5), "1e+06");
        assert_eq!(g(2.220446049250313e-16), "2.22045e-16");
        assert_eq!(g(-2.55836e-17), "-2.55836e-17");
        assert_eq!(g(3.082704), "3.0827");
        assert_eq!(g(1.0 / 3.0), "0.333333");
        assert_eq!(g(-12.0), "-12");
        assert_eq!(g(0.00617284), "0.00617284");
    }

    #[test]
    fn rounding_equals_parsing_the_text() {
        let mut x = 1.234567891e-9;
        let mut state = 0x9e3779b97f4a7c15u64;
        for _ in 0..200_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let m = (state >> 11) as f64 / (1u64 << 53) as f64;
            x = (m - 0.5) * 10f64.powi(((state >> 3) % 40) as i32 - 20);
            let text: f64 = g(x).parse().unwrap();
            assert_eq!(round_g6(x).to_bits(), text.to_bits(), "{x:e}");
        }
        assert_eq!(round_g6(x), round_g6(round_g6(x)));
        for v in [
            0.5f64,
            1.5,
            2.5,
            0.125,
            1e22,
            1e-30,
            123456.5,
            999999.5,
            0.0009765625,
            0.0029296875,
            -0.001953125,
            1234567.0,
            3.0e7,
        ] {
            let text: f64 = g(v).parse().unwrap();
            assert_eq!(round_g6(v), text, "{v}");
        }
    }
}
