//! Special functions for the tests' null distributions, in `f64`.
//!
//! Everything is built on two classic kernels, both from *Numerical Recipes* (Press, Teukolsky,
//! Vetterling, Flannery, 3rd ed., 2007):
//!
//! * the regularised incomplete gamma functions P(a, x) and Q(a, x) (§6.2: power series for
//!   x < a + 1, Legendre's continued fraction evaluated by the modified Lentz method otherwise);
//! * the regularised incomplete beta function I_x(a, b) (§6.4: the continued fraction, with the
//!   symmetry I_x(a, b) = 1 − I_{1−x}(b, a) to stay in its fast-converging region).
//!
//! ln Γ is Lanczos' approximation with g = 7 and 9 coefficients (Lanczos 1964; the coefficient set
//! of Godfrey, as in Press et al. and many libraries), good to about 1e-15 relative for x ≥ 1/2.
//!
//! The distributions follow from them:
//!
//! * χ² survival: Q(ν/2, x/2) (Abramowitz & Stegun 26.4.19);
//! * two-sided normal tail 2·Φ(−|z|) = erfc(|z|/√2) = Q(1/2, z²/2) (A&S 7.1.2, 6.5.17);
//! * two-sided Student-t tail P(|T| > t) = I_{ν/(ν+t²)}(ν/2, 1/2) (A&S 26.7.1, 26.5.27).
//!
//! Computing the normal tail through Q keeps full relative accuracy far into the tail, where
//! `1 − Φ` would cancel. Agreement with scipy (Cephes / Boost kernels) is checked by the fixture
//! test in `reference_tests.rs`.

/// Relative convergence threshold of the series and continued fractions.
const EPS: f64 = f64::EPSILON;
/// Smallest magnitude the Lentz recurrences may reach before being nudged (NR's `FPMIN`).
const FPMIN: f64 = f64::MIN_POSITIVE / f64::EPSILON;
/// Iteration cap of the series and continued fractions; convergence takes O(√a) terms, so this is
/// only reached on arguments far beyond what the tests produce.
const MAX_ITER: usize = 100_000;

/// Lanczos coefficients for g = 7, n = 9.
const LANCZOS_G: f64 = 7.0;
const LANCZOS: [f64; 9] = [
    0.999_999_999_999_809_9,
    676.520_368_121_885_1,
    -1_259.139_216_722_402_8,
    771.323_428_777_653_1,
    -176.615_029_162_140_6,
    12.507_343_278_686_905,
    -0.138_571_095_265_720_12,
    9.984_369_578_019_572e-6,
    1.505_632_735_149_311_6e-7,
];

/// ln Γ(x) for x > 0 (Lanczos, g = 7, n = 9; reflection Γ(x)Γ(1−x) = π / sin(πx) below 1/2).
pub(crate) fn ln_gamma(x: f64) -> f64 {
    debug_assert!(x > 0.0, "ln_gamma needs x > 0, got {x}");
    if x < 0.5 {
        // Reflection keeps the Lanczos sum in its accurate range.
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut sum = LANCZOS[0];
    for (i, c) in LANCZOS.iter().enumerate().skip(1) {
        sum += c / (x + i as f64);
    }
    let t = x + LANCZOS_G + 0.5;
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

/// The common prefactor x^a e^{−x} / Γ(a) of the incomplete gamma series and fraction.
fn gamma_prefactor(a: f64, x: f64) -> f64 {
    (a * x.ln() - x - ln_gamma(a)).exp()
}

/// P(a, x) by its power series (NR `gser`); converges fast for x < a + 1.
fn gamma_p_series(a: f64, x: f64) -> f64 {
    let mut ap = a;
    let mut del = 1.0 / a;
    let mut sum = del;
    for _ in 0..MAX_ITER {
        ap += 1.0;
        del *= x / ap;
        sum += del;
        if del.abs() < sum.abs() * EPS {
            break;
        }
    }
    sum * gamma_prefactor(a, x)
}

/// Q(a, x) by Legendre's continued fraction, modified Lentz (NR `gcf`); for x ≥ a + 1.
fn gamma_q_fraction(a: f64, x: f64) -> f64 {
    let mut b = x + 1.0 - a;
    let mut c = 1.0 / FPMIN;
    let mut d = 1.0 / b;
    let mut h = d;
    for i in 1..MAX_ITER {
        let an = -(i as f64) * (i as f64 - a);
        b += 2.0;
        d = an * d + b;
        if d.abs() < FPMIN {
            d = FPMIN;
        }
        c = b + an / c;
        if c.abs() < FPMIN {
            c = FPMIN;
        }
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() <= EPS {
            break;
        }
    }
    gamma_prefactor(a, x) * h
}

/// Regularised upper incomplete gamma Q(a, x) = Γ(a, x) / Γ(a), for a > 0 and x ≥ 0.
pub(crate) fn gamma_q(a: f64, x: f64) -> f64 {
    debug_assert!(
        a > 0.0 && x >= 0.0,
        "gamma_q needs a > 0, x >= 0 (a {a}, x {x})"
    );
    if x <= 0.0 {
        1.0
    } else if x.is_infinite() {
        0.0
    } else if x < a + 1.0 {
        1.0 - gamma_p_series(a, x)
    } else {
        gamma_q_fraction(a, x)
    }
}

/// Continued fraction of the incomplete beta function (NR `betacf`), modified Lentz.
fn beta_fraction(a: f64, b: f64, x: f64) -> f64 {
    let qab = a + b;
    let qap = a + 1.0;
    let qam = a - 1.0;
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < FPMIN {
        d = FPMIN;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..MAX_ITER {
        let m = m as f64;
        let m2 = 2.0 * m;
        // Even step.
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 + aa * d;
        if d.abs() < FPMIN {
            d = FPMIN;
        }
        c = 1.0 + aa / c;
        if c.abs() < FPMIN {
            c = FPMIN;
        }
        d = 1.0 / d;
        h *= d * c;
        // Odd step.
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 + aa * d;
        if d.abs() < FPMIN {
            d = FPMIN;
        }
        c = 1.0 + aa / c;
        if c.abs() < FPMIN {
            c = FPMIN;
        }
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() <= EPS {
            break;
        }
    }
    h
}

/// Regularised incomplete beta I_x(a, b) for a, b > 0, given both `x` and `y = 1 − x` so the
/// caller can pass the complement computed without cancellation.
pub(crate) fn beta_inc(a: f64, b: f64, x: f64, y: f64) -> f64 {
    debug_assert!(a > 0.0 && b > 0.0, "beta_inc needs a, b > 0 (a {a}, b {b})");
    if x <= 0.0 {
        return 0.0;
    }
    if y <= 0.0 {
        return 1.0;
    }
    let front = (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * y.ln()).exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_fraction(a, b, x) / a
    } else {
        1.0 - front * beta_fraction(b, a, y) / b
    }
}

/// χ² survival function P(X > x) with `df` degrees of freedom: Q(df/2, x/2).
pub(crate) fn chi2_sf(x: f64, df: f64) -> f64 {
    if x <= 0.0 {
        1.0
    } else {
        gamma_q(0.5 * df, 0.5 * x)
    }
}

/// Two-sided standard normal tail P(|Z| ≥ |z|) = erfc(|z|/√2) = Q(1/2, z²/2).
pub(crate) fn normal_two_sided(z: f64) -> f64 {
    gamma_q(0.5, 0.5 * z * z)
}

/// Standard normal survival function P(Z > z), via [`normal_two_sided`] for z ≥ 0.
pub(crate) fn normal_sf(z: f64) -> f64 {
    if z >= 0.0 {
        0.5 * normal_two_sided(z)
    } else {
        1.0 - 0.5 * normal_two_sided(z)
    }
}

/// Two-sided Student-t tail P(|T| ≥ |t|) with `df` degrees of freedom:
/// I_{df/(df+t²)}(df/2, 1/2).
pub(crate) fn student_t_two_sided(t: f64, df: f64) -> f64 {
    if t.is_infinite() {
        return 0.0;
    }
    let t2 = t * t;
    let x = df / (df + t2);
    let y = t2 / (df + t2);
    beta_inc(0.5 * df, 0.5, x, y)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, rel: f64) -> bool {
        (a - b).abs() <= rel * b.abs()
    }

    /// Values from closed forms: Γ(n) = (n−1)!, Γ(1/2) = √π.
    #[test]
    fn ln_gamma_known_values() {
        assert!(ln_gamma(1.0).abs() < 1e-15);
        assert!(ln_gamma(2.0).abs() < 1e-15);
        assert!(close(ln_gamma(10.0), 362_880f64.ln(), 1e-14));
        assert!(close(
            ln_gamma(0.5),
            std::f64::consts::PI.sqrt().ln(),
            1e-14
        ));
        assert!(close(ln_gamma(0.25), 3.625_609_908_221_908_f64.ln(), 1e-14));
    }

    /// Closed forms: χ²(2) survival is e^{−x/2}; erfc(1/√2) = 0.31731050786291415 (A&S table 26.1).
    #[test]
    fn distributions_against_closed_forms() {
        for x in [0.1, 1.0, 6.2, 30.0, 200.0] {
            assert!(close(chi2_sf(x, 2.0), (-x / 2.0).exp(), 1e-14), "x {x}");
        }
        assert!(close(
            normal_two_sided(1.0),
            0.317_310_507_862_914_15,
            1e-14
        ));
        assert!(close(normal_two_sided(1.959_963_984_540_054), 0.05, 1e-13));
        // Student t with 1 df is Cauchy: P(|T| > t) = 1 − 2 atan(t)/π.
        for t in [0.3_f64, 1.0, 4.0] {
            let cauchy = 1.0 - 2.0 * f64::atan(t) / std::f64::consts::PI;
            assert!(close(student_t_two_sided(t, 1.0), cauchy, 1e-13), "t {t}");
        }
        // And with 2 df: P(|T| > t) = 1 − t / √(2 + t²).
        for t in [0.3_f64, 1.0, 4.0] {
            let closed = 1.0 - t / (2.0 + t * t).sqrt();
            assert!(close(student_t_two_sided(t, 2.0), closed, 1e-13), "t {t}");
        }
    }
}
