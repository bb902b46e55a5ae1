//! Statistics for policy A/B experiments and the paper's validation (`assess::spec` §9, issue 5).
//!
//! Pure `f64`, no dependencies. Every test is two-sided and matches scipy 1.17 (`scipy.stats`)
//! where scipy has it; `scripts/stats_reference.py` writes scipy's answers on seeded data into
//! `src/stats/scipy_reference.json`, which `reference_tests.rs` checks.
//!
//! | function | what | scipy counterpart |
//! |---|---|---|
//! | [`wilcoxon`] | paired signed-rank test, zero handling [`ZeroMethod`], exact / permutation / normal | `wilcoxon(x, y, zero_method, correction, method="auto")` |
//! | [`friedman`] | Friedman χ² with the tie correction, Kendall's W | `friedmanchisquare` |
//! | [`holm`] | Holm step-down adjusted p-values | (none; statsmodels `multipletests(method="holm")`) |
//! | [`spearman`] | Spearman ρ, p by t-approximation or exact permutation | `spearmanr`; `permutation_test(..., permutation_type="pairings")` |
//! | [`raw_tlx`] | Raw NASA-TLX: mean of six 0–20 ratings | — |
//!
//! Ranks are average ranks (midranks). Internally they are handled doubled (2·rank is an integer),
//! so the permutation tests compare statistics exactly, as scipy's tolerance-based comparison
//! intends.

// The experiment command wires these in (issue 5); until it does, not everything has a caller.
#![allow(dead_code)]

mod special;

#[cfg(test)]
mod reference_tests;

use std::fmt;

pub(crate) use special::{chi2_sf, student_t_two_sided};

/// Why a statistic could not be computed.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum StatsError {
    /// An input was NaN or infinite.
    NotFinite(&'static str),
    /// Inputs that must pair up have different lengths.
    LengthMismatch { left: usize, right: usize },
    /// Too few observations for the test.
    TooFew {
        what: &'static str,
        n: usize,
        min: usize,
    },
    /// The statistic is undefined for these data (e.g. all differences zero, a constant sample).
    Degenerate(&'static str),
    /// A value outside its allowed range.
    OutOfRange { what: &'static str, value: f64 },
}

impl fmt::Display for StatsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotFinite(what) => write!(f, "{what}: every value must be finite"),
            Self::LengthMismatch { left, right } => {
                write!(f, "paired samples differ in length ({left} vs {right})")
            }
            Self::TooFew { what, n, min } => {
                write!(f, "{what}: {n} observations, need at least {min}")
            }
            Self::Degenerate(why) => write!(f, "statistic undefined: {why}"),
            Self::OutOfRange { what, value } => write!(f, "{what}: {value} is out of range"),
        }
    }
}

impl std::error::Error for StatsError {}

fn check_finite(xs: &[f64], what: &'static str) -> Result<(), StatsError> {
    if xs.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(StatsError::NotFinite(what))
    }
}

/// Doubled average ranks (2·midrank, an integer) of `xs`, 1-based, and the sizes of the tie
/// groups (one entry per distinct value, singletons included). `xs` must be finite.
fn doubled_ranks(xs: &[f64]) -> (Vec<i64>, Vec<usize>) {
    let mut order: Vec<usize> = (0..xs.len()).collect();
    order.sort_by(|&a, &b| xs[a].total_cmp(&xs[b]));
    let mut ranks = vec![0_i64; xs.len()];
    let mut groups = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let mut end = start + 1;
        while end < order.len() && xs[order[end]] == xs[order[start]] {
            end += 1;
        }
        // Positions start+1 ..= end share the rank (start+1+end)/2; doubled: start+1+end.
        let doubled = (start + 1 + end) as i64;
        for &i in &order[start..end] {
            ranks[i] = doubled;
        }
        groups.push(end - start);
        start = end;
    }
    (ranks, groups)
}

/// Average ranks (midranks, 1-based) of finite values, as scipy's `rankdata(method="average")`.
pub(crate) fn average_ranks(xs: &[f64]) -> Result<Vec<f64>, StatsError> {
    check_finite(xs, "ranks")?;
    Ok(doubled_ranks(xs)
        .0
        .into_iter()
        .map(|r| r as f64 / 2.0)
        .collect())
}

// ---------------------------------------------------------------------------------------------
// Wilcoxon signed-rank

/// How the Wilcoxon signed-rank test treats zero differences (ties between the pair members).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) enum ZeroMethod {
    /// Wilcoxon (1945): drop zero differences, then rank the rest. scipy's default.
    #[default]
    Wilcox,
    /// Pratt (1959): rank the zeros with the others (they take the smallest ranks), then leave
    /// their ranks out of both sums; the normal approximation is adjusted as in Cureton (1967).
    Pratt,
    /// Zero-split: rank the zeros with the others and give half of their rank sum to each of R⁺
    /// and R⁻.
    Zsplit,
}

/// Which null distribution gives the Wilcoxon p-value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) enum WilcoxonMethod {
    /// scipy's `method="auto"`: the exact distribution when n ≤ 50 and there are neither ties
    /// nor zeros; otherwise the exact sign-flip permutation distribution when n ≤ 13 (n counts
    /// the zeros); otherwise the normal approximation.
    #[default]
    Auto,
    /// The exact null distribution of R⁺ (valid without ties and zeros; with them, R⁺ is rounded
    /// conservatively, as scipy does). n ≤ 63.
    Exact,
    /// The exact distribution over all 2ⁿ sign flips of the differences (valid with ties and
    /// zeros). n ≤ 24.
    Permutation,
    /// The normal approximation with the tie correction of the variance.
    Asymptotic,
}

/// Options of [`wilcoxon`]; the default is scipy's default except `correction`, which scipy's
/// `wilcoxon` also defaults to `false`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct WilcoxonOptions {
    /// Zero handling.
    pub(crate) zero_method: ZeroMethod,
    /// Continuity correction (±½ on R⁺) in the normal approximation; ignored by exact methods.
    pub(crate) correction: bool,
    /// Null distribution.
    pub(crate) method: WilcoxonMethod,
}

/// The result of [`wilcoxon`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct WilcoxonResult {
    /// min(R⁺, R⁻), scipy's two-sided statistic.
    pub(crate) statistic: f64,
    /// Sum of the ranks of the positive differences (x > y), after zero handling.
    pub(crate) r_plus: f64,
    /// Sum of the ranks of the negative differences, after zero handling.
    pub(crate) r_minus: f64,
    /// Number of pairs.
    pub(crate) n: usize,
    /// Number of zero differences among them.
    pub(crate) n_zero: usize,
    /// The standardised statistic (R⁺ − mean)/sd with the continuity correction if asked, when
    /// the normal approximation was used.
    pub(crate) z: Option<f64>,
    /// Two-sided p-value.
    pub(crate) p_value: f64,
    /// The method that gave the p-value (never `Auto`).
    pub(crate) method: WilcoxonMethod,
    /// Matched-pairs rank-biserial correlation (R⁺ − R⁻)/(R⁺ + R⁻) (Kerby 2014), in [−1, 1];
    /// positive when x tends to exceed y.
    pub(crate) rank_biserial: f64,
}

/// The rank sums of one signed-rank evaluation, doubled (integers).
struct SignedRanks {
    /// 2·R⁺ and 2·R⁻ (zsplit adds the halves: both stay integers since ranks are doubled and a
    /// half of a doubled rank sum is a plain rank sum).
    plus2: i64,
    minus2: i64,
}

/// Doubled rank sums of `d` under `zero_method`, from the doubled ranks of |d| (zeros included
/// or excluded as the method says).
fn signed_rank_sums(d: &[f64], ranks2: &[i64], zero_method: ZeroMethod) -> SignedRanks {
    let (mut plus2, mut minus2, mut zero2) = (0_i64, 0_i64, 0_i64);
    for (&di, &r) in d.iter().zip(ranks2) {
        if di > 0.0 {
            plus2 += r;
        } else if di < 0.0 {
            minus2 += r;
        } else {
            zero2 += r;
        }
    }
    if zero_method == ZeroMethod::Zsplit {
        // Half of the zeros' rank sum to each side. Doubled values: add zero2/2 each; zero2 is a
        // sum of doubled ranks 2·r over the zeros, whose ranks are 1..=z averaged, so
        // zero2 = z(z+1), always even.
        plus2 += zero2 / 2;
        minus2 += zero2 / 2;
    }
    SignedRanks { plus2, minus2 }
}

/// Wilcoxon signed-rank test of the paired samples `x`, `y` (differences d = x − y), two-sided.
///
/// Ranks are midranks of |d|. Zeros are handled by `options.zero_method`; the p-value comes from
/// `options.method` (see [`WilcoxonMethod`]; `Auto` chooses as scipy does). In the normal
/// approximation the mean and variance of R⁺ are n(n+1)/4 and
/// [n(n+1)(2n+1) − ½Σ(t³ − t)]/24 over the ranked differences (t: tie group sizes), with Pratt's
/// zeros subtracted as in Cureton (1967).
pub(crate) fn wilcoxon(
    x: &[f64],
    y: &[f64],
    options: WilcoxonOptions,
) -> Result<WilcoxonResult, StatsError> {
    if x.len() != y.len() {
        return Err(StatsError::LengthMismatch {
            left: x.len(),
            right: y.len(),
        });
    }
    check_finite(x, "wilcoxon x")?;
    check_finite(y, "wilcoxon y")?;
    let d: Vec<f64> = x.iter().zip(y).map(|(a, b)| a - b).collect();
    wilcoxon_differences(&d, options)
}

/// [`wilcoxon`] on the differences themselves (one-sample test of symmetry about zero).
pub(crate) fn wilcoxon_differences(
    d: &[f64],
    options: WilcoxonOptions,
) -> Result<WilcoxonResult, StatsError> {
    check_finite(d, "wilcoxon differences")?;
    let n = d.len();
    let n_zero = d.iter().filter(|&&v| v == 0.0).count();
    // The differences that are ranked: the non-zero ones for Wilcox, all for Pratt and zsplit.
    let ranked: Vec<f64> = match options.zero_method {
        ZeroMethod::Wilcox => d.iter().copied().filter(|&v| v != 0.0).collect(),
        ZeroMethod::Pratt | ZeroMethod::Zsplit => d.to_vec(),
    };
    let count = ranked.len();
    if n_zero == n {
        return Err(StatsError::Degenerate("every difference is zero"));
    }
    let abs: Vec<f64> = ranked.iter().map(|v| v.abs()).collect();
    let (ranks2, groups) = doubled_ranks(&abs);
    let has_ties = groups.iter().any(|&t| t > 1);
    let sums = signed_rank_sums(&ranked, &ranks2, options.zero_method);
    let r_plus = sums.plus2 as f64 / 2.0;
    let r_minus = sums.minus2 as f64 / 2.0;

    let method = match options.method {
        WilcoxonMethod::Auto if n > 50 => WilcoxonMethod::Asymptotic,
        WilcoxonMethod::Auto if !has_ties && n_zero == 0 => WilcoxonMethod::Exact,
        WilcoxonMethod::Auto if n <= 13 => WilcoxonMethod::Permutation,
        WilcoxonMethod::Auto => WilcoxonMethod::Asymptotic,
        m => m,
    };

    let mut z = None;
    let p_value = match method {
        WilcoxonMethod::Exact => {
            if count > 63 {
                return Err(StatsError::OutOfRange {
                    what: "exact Wilcoxon n",
                    value: count as f64,
                });
            }
            wilcoxon_exact_p(count, r_plus)
        }
        WilcoxonMethod::Permutation => {
            if n > 24 {
                return Err(StatsError::OutOfRange {
                    what: "permutation Wilcoxon n",
                    value: n as f64,
                });
            }
            wilcoxon_permutation_p(d, options.zero_method)
        }
        WilcoxonMethod::Asymptotic | WilcoxonMethod::Auto => {
            let c = count as f64;
            let mut mean = c * (c + 1.0) * 0.25;
            let mut var24 = c * (c + 1.0) * (2.0 * c + 1.0);
            let mut ties: f64 = groups.iter().map(|&t| (t * t * t - t) as f64).sum();
            if options.zero_method == ZeroMethod::Pratt && n_zero > 0 {
                let z0 = n_zero as f64;
                mean -= z0 * (z0 + 1.0) * 0.25;
                var24 -= z0 * (z0 + 1.0) * (2.0 * z0 + 1.0);
                // The zeros are the first tie group of |d| and do not enter the tie correction.
                ties -= (n_zero * n_zero * n_zero - n_zero) as f64;
            }
            let se = ((var24 - ties / 2.0) / 24.0).sqrt();
            let mut zz = (r_plus - mean) / se;
            if options.correction {
                zz -= zz.signum() * 0.5 / se;
            }
            z = Some(zz);
            special::normal_two_sided(zz).min(1.0)
        }
    };
    let total = r_plus + r_minus;
    Ok(WilcoxonResult {
        statistic: r_plus.min(r_minus),
        r_plus,
        r_minus,
        n,
        n_zero,
        z,
        p_value,
        method,
        rank_biserial: if total > 0.0 {
            (r_plus - r_minus) / total
        } else {
            0.0
        },
    })
}

/// Counts of the exact null distribution of R⁺ for n untied non-zero differences: entry w is the
/// number of subsets of {1, …, n} summing to w (total 2ⁿ).
fn wilcoxon_counts(n: usize) -> Vec<u64> {
    let max = n * (n + 1) / 2;
    let mut counts = vec![0_u64; max + 1];
    counts[0] = 1;
    for k in 1..=n {
        for w in (k..=k * (k + 1) / 2).rev() {
            counts[w] += counts[w - k];
        }
    }
    counts
}

/// Two-sided exact p-value 2·min(P(R⁺ ≥ ⌊r⌋), P(R⁺ ≤ ⌈r⌉)), capped at 1 (scipy's rule).
///
/// Every probability is a count over 2ⁿ, a dyadic rational with numerator below 2⁵³ (n ≤ 52), so
/// it is exact in `f64` whatever the summation order: bit-identical to scipy's.
fn wilcoxon_exact_p(n: usize, r_plus: f64) -> f64 {
    let counts = wilcoxon_counts(n);
    let total = 2f64.powi(n as i32);
    let lo = r_plus.floor() as usize;
    let hi = r_plus.ceil() as usize;
    let sf: u64 = counts[lo.min(counts.len())..].iter().sum();
    let cdf: u64 = counts[..=hi.min(counts.len() - 1)].iter().sum();
    (2.0 * (sf.min(cdf) as f64 / total)).min(1.0)
}

/// Two-sided p-value over all 2ⁿ sign flips of `d`: 2·min(#{R⁺* ≤ R⁺}, #{R⁺* ≥ R⁺})/2ⁿ, capped
/// at 1, as scipy's `permutation_test(permutation_type="samples")` computes it exactly.
fn wilcoxon_permutation_p(d: &[f64], zero_method: ZeroMethod) -> f64 {
    let ranked: Vec<f64> = match zero_method {
        ZeroMethod::Wilcox => d.iter().copied().filter(|&v| v != 0.0).collect(),
        ZeroMethod::Pratt | ZeroMethod::Zsplit => d.to_vec(),
    };
    let abs: Vec<f64> = ranked.iter().map(|v| v.abs()).collect();
    let (ranks2, _) = doubled_ranks(&abs);
    // Only the non-zero differences change R⁺ when flipped; the zeros' flips only multiply the
    // counts by 2^(zeros), which cancels in the ratio but is kept to match scipy's denominator.
    let free: Vec<i64> = ranked
        .iter()
        .zip(&ranks2)
        .filter(|(v, _)| **v != 0.0)
        .map(|(_, &r)| r)
        .collect();
    let base = signed_rank_sums(&ranked, &ranks2, zero_method);
    // Doubled R⁺ = constant (zsplit's half of the zeros) + the doubled ranks flipped positive.
    let constant = base.plus2
        - ranked
            .iter()
            .zip(&ranks2)
            .filter(|(v, _)| **v > 0.0)
            .map(|(_, &r)| r)
            .sum::<i64>();
    let observed = base.plus2;
    let (mut le, mut ge) = (0_u64, 0_u64);
    for mask in 0_u64..(1 << free.len()) {
        let mut s = constant;
        for (i, r) in free.iter().enumerate() {
            if mask >> i & 1 == 1 {
                s += r;
            }
        }
        le += u64::from(s <= observed);
        ge += u64::from(s >= observed);
    }
    let zeros = (d.len() - free.len()) as u32;
    let total = 2f64.powi(d.len() as i32);
    let (le, ge) = (le << zeros, ge << zeros);
    (le.min(ge) as f64 / total * 2.0).min(1.0)
}

// ---------------------------------------------------------------------------------------------
// Friedman

/// The result of [`friedman`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FriedmanResult {
    /// The tie-corrected Friedman χ² statistic.
    pub(crate) statistic: f64,
    /// Degrees of freedom, k − 1.
    pub(crate) df: usize,
    /// P(χ²_df ≥ statistic).
    pub(crate) p_value: f64,
    /// Number of blocks (participants).
    pub(crate) n: usize,
    /// Number of conditions (treatments).
    pub(crate) k: usize,
    /// The tie correction factor C = 1 − Σ(t³ − t) / (n k (k² − 1)) the raw statistic was divided by.
    pub(crate) tie_correction: f64,
    /// Kendall's coefficient of concordance W = χ² / (n (k − 1)), tie-corrected with χ², in [0, 1].
    pub(crate) kendall_w: f64,
}

/// Friedman test: `blocks[i][j]` is participant i's value under condition j (every block the
/// same length k ≥ 2; scipy asks for k ≥ 3, but the statistic is defined for k = 2 too).
///
/// Values are ranked within each block (midranks); with R_j the rank sum of condition j,
/// χ² = [12/(n k (k+1)) Σ R_j² − 3 n (k+1)] / C, C the tie correction above (Conover 1999,
/// §5.8; scipy's `friedmanchisquare`). The p-value is the χ²(k − 1) tail.
pub(crate) fn friedman<B: AsRef<[f64]>>(blocks: &[B]) -> Result<FriedmanResult, StatsError> {
    let n = blocks.len();
    if n < 2 {
        return Err(StatsError::TooFew {
            what: "Friedman blocks",
            n,
            min: 2,
        });
    }
    let k = blocks[0].as_ref().len();
    if k < 2 {
        return Err(StatsError::TooFew {
            what: "Friedman conditions",
            n: k,
            min: 2,
        });
    }
    let mut rank_sums2 = vec![0_i64; k];
    let mut ties = 0_u64;
    for block in blocks {
        let block = block.as_ref();
        if block.len() != k {
            return Err(StatsError::LengthMismatch {
                left: k,
                right: block.len(),
            });
        }
        check_finite(block, "Friedman values")?;
        let (ranks2, groups) = doubled_ranks(block);
        for (s, r) in rank_sums2.iter_mut().zip(ranks2) {
            *s += r;
        }
        ties += groups.iter().map(|&t| (t * t * t - t) as u64).sum::<u64>();
    }
    let (nf, kf) = (n as f64, k as f64);
    let c = 1.0 - ties as f64 / (kf * (kf * kf - 1.0) * nf);
    if c <= 0.0 {
        return Err(StatsError::Degenerate("every block is fully tied"));
    }
    let ssbn: f64 = rank_sums2.iter().map(|&s| (s as f64 / 2.0).powi(2)).sum();
    let statistic = (12.0 / (kf * nf * (kf + 1.0)) * ssbn - 3.0 * nf * (kf + 1.0)) / c;
    Ok(FriedmanResult {
        statistic,
        df: k - 1,
        p_value: chi2_sf(statistic, (k - 1) as f64),
        n,
        k,
        tie_correction: c,
        kendall_w: statistic / (nf * (kf - 1.0)),
    })
}

// ---------------------------------------------------------------------------------------------
// Holm

/// Holm's (1979) step-down adjusted p-values, in the input order: with p₍₁₎ ≤ … ≤ p₍ₘ₎,
/// p̃₍ᵢ₎ = max_{j ≤ i} min(1, (m − j + 1) p₍ⱼ₎). Monotone in the sorted order and capped at 1;
/// reject hypothesis i at family-wise level α iff p̃ᵢ ≤ α. Same as statsmodels'
/// `multipletests(method="holm")`.
pub(crate) fn holm(p_values: &[f64]) -> Result<Vec<f64>, StatsError> {
    if p_values.iter().any(|p| !(0.0..=1.0).contains(p)) {
        let bad = p_values
            .iter()
            .copied()
            .find(|p| !(0.0..=1.0).contains(p))
            .unwrap_or(f64::NAN);
        return Err(StatsError::OutOfRange {
            what: "p-value",
            value: bad,
        });
    }
    let m = p_values.len();
    let mut order: Vec<usize> = (0..m).collect();
    // Stable sort: equal p-values keep their input order (the adjusted values are equal anyway).
    order.sort_by(|&a, &b| p_values[a].total_cmp(&p_values[b]));
    let mut adjusted = vec![0.0; m];
    let mut running = 0.0_f64;
    for (j, &i) in order.iter().enumerate() {
        running = running.max(((m - j) as f64 * p_values[i]).min(1.0));
        adjusted[i] = running;
    }
    Ok(adjusted)
}

// ---------------------------------------------------------------------------------------------
// Spearman

/// Which null distribution gives the Spearman p-value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) enum SpearmanMethod {
    /// Exact permutation for n ≤ 10 (10! = 3 628 800 pairings), t-approximation above.
    #[default]
    Auto,
    /// t = ρ √((n − 2)/(1 − ρ²)) on n − 2 degrees of freedom (scipy's `spearmanr` p-value).
    TApproximation,
    /// All n! pairings of y with x; p = 2·min(#{ρ* ≤ ρ}, #{ρ* ≥ ρ})/n!, capped at 1 (scipy's
    /// `permutation_test(permutation_type="pairings", n_resamples=inf)`). Valid with ties. n ≤ 12.
    ExactPermutation,
}

/// The result of [`spearman`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SpearmanResult {
    /// Spearman's ρ: Pearson's correlation of the midranks.
    pub(crate) rho: f64,
    /// Two-sided p-value.
    pub(crate) p_value: f64,
    /// The method that gave the p-value (never `Auto`).
    pub(crate) method: SpearmanMethod,
    /// Number of pairs.
    pub(crate) n: usize,
}

/// Spearman's rank correlation of `x` and `y` with a two-sided p-value (`assess::spec` §9: per
/// participant; the method is part of the result so reports can state it).
pub(crate) fn spearman(
    x: &[f64],
    y: &[f64],
    method: SpearmanMethod,
) -> Result<SpearmanResult, StatsError> {
    if x.len() != y.len() {
        return Err(StatsError::LengthMismatch {
            left: x.len(),
            right: y.len(),
        });
    }
    check_finite(x, "spearman x")?;
    check_finite(y, "spearman y")?;
    let n = x.len();
    if n < 3 {
        return Err(StatsError::TooFew {
            what: "Spearman pairs",
            n,
            min: 3,
        });
    }
    let (rx, _) = doubled_ranks(x);
    let (ry, _) = doubled_ranks(y);
    // Centred doubled ranks: 2r − (n+1) is an integer; ρ is their Pearson correlation.
    let centre = (n + 1) as i64;
    let cx: Vec<i64> = rx.iter().map(|r| r - centre).collect();
    let cy: Vec<i64> = ry.iter().map(|r| r - centre).collect();
    let sxx: i64 = cx.iter().map(|v| v * v).sum();
    let syy: i64 = cy.iter().map(|v| v * v).sum();
    if sxx == 0 || syy == 0 {
        return Err(StatsError::Degenerate("a sample is constant"));
    }
    let sxy: i64 = cx.iter().zip(&cy).map(|(a, b)| a * b).sum();
    let rho = (sxy as f64 / (sxx as f64 * syy as f64).sqrt()).clamp(-1.0, 1.0);
    let method = match method {
        SpearmanMethod::Auto if n <= 10 => SpearmanMethod::ExactPermutation,
        SpearmanMethod::Auto => SpearmanMethod::TApproximation,
        m => m,
    };
    let p_value = match method {
        SpearmanMethod::ExactPermutation => {
            if n > 12 {
                return Err(StatsError::OutOfRange {
                    what: "exact Spearman n",
                    value: n as f64,
                });
            }
            spearman_permutation_p(&cx, &cy, sxy)
        }
        _ => {
            let df = (n - 2) as f64;
            if rho.abs() >= 1.0 {
                0.0
            } else {
                let t = rho * (df / ((1.0 + rho) * (1.0 - rho))).sqrt();
                student_t_two_sided(t, df)
            }
        }
    };
    Ok(SpearmanResult {
        rho,
        p_value,
        method,
        n,
    })
}

/// Exact two-sided permutation p-value of Σ cx·cy over all n! orders of `cy` (Heap's algorithm;
/// each swap updates the sum in O(1), integers throughout).
fn spearman_permutation_p(cx: &[i64], cy: &[i64], observed: i64) -> f64 {
    let n = cy.len();
    let mut y = cy.to_vec();
    let mut s = observed;
    let (mut le, mut ge) = (1_u64, 1_u64); // the identity permutation
    let mut total = 1_u64;
    let mut c = vec![0_usize; n];
    let mut i = 1;
    while i < n {
        if c[i] < i {
            let j = if i % 2 == 0 { 0 } else { c[i] };
            // Swapping y[j] and y[i] changes Σ cx·y by (cx_j − cx_i)(y_i − y_j).
            s += (cx[j] - cx[i]) * (y[i] - y[j]);
            y.swap(j, i);
            le += u64::from(s <= observed);
            ge += u64::from(s >= observed);
            total += 1;
            c[i] += 1;
            i = 1;
        } else {
            c[i] = 0;
            i += 1;
        }
    }
    (le.min(ge) as f64 / total as f64 * 2.0).min(1.0)
}

// ---------------------------------------------------------------------------------------------
// NASA-TLX

/// Raw NASA-TLX (Hart 2006, "RTLX"): the unweighted mean of the six subscale ratings (mental,
/// physical and temporal demand, performance, effort, frustration), each on the 0–20 scale.
/// Ratings must be finite and within [0, 20]; the result is on the same scale.
pub(crate) fn raw_tlx(ratings: [f64; 6]) -> Result<f64, StatsError> {
    for r in ratings {
        if !r.is_finite() || !(0.0..=20.0).contains(&r) {
            return Err(StatsError::OutOfRange {
                what: "NASA-TLX rating (0–20)",
                value: r,
            });
        }
    }
    Ok(ratings.iter().sum::<f64>() / 6.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `assess::spec` §9: the paper's χ²(2) figures and their p-values (3 decimals).
    #[test]
    fn paper_chi2_figures() {
        for (chi2, p) in [(6.20, 0.045), (6.70, 0.035), (6.82, 0.033)] {
            let got = chi2_sf(chi2, 2.0);
            assert!((got - p).abs() < 5e-4, "χ²(2) = {chi2}: p {got}, paper {p}");
        }
    }

    /// The paper's χ²(2) = 6.82 with n = 10 is impossible untied: 12/(n k (k+1)) Σ R² − 3n(k+1)
    /// takes values in steps of 12·2/120 = 0.2 ... only with ties does 6.82 appear. A constructed
    /// tied data set: the tie correction raises 6.2 to 6.2 / C.
    #[test]
    fn friedman_tie_correction() {
        // n = 10 participants, k = 3; one block fully ordered the same way, with two tied pairs.
        let mut blocks = vec![[1.0, 2.0, 3.0]; 6];
        blocks.extend([
            [2.0, 1.0, 3.0],
            [3.0, 2.0, 1.0],
            [1.0, 1.0, 2.0],
            [2.0, 2.0, 1.0],
        ]);
        let r = friedman(&blocks).unwrap();
        // Rank sums: 6·(1,2,3) + (2,1,3) + (3,2,1) + (1.5,1.5,3) + (2.5,2.5,1) = (15, 19, 26).
        // Raw: 12/120·(225+361+676) − 120 = 6.2; ties: 2 groups of 2 → Σ(t³−t) = 12,
        // C = 1 − 12/(3·8·10) = 0.95, χ² = 6.2/0.95.
        assert!((r.tie_correction - 0.95).abs() < 1e-15);
        assert!((r.statistic - 6.2 / 0.95).abs() < 1e-12);
        assert_eq!(r.df, 2);
        assert!((r.kendall_w - r.statistic / 20.0).abs() < 1e-15);
    }

    #[test]
    fn holm_adjusts_monotone_and_capped() {
        let adj = holm(&[0.01, 0.04, 0.03, 0.5]).unwrap();
        // Sorted 0.01, 0.03, 0.04, 0.5 → 0.04, 0.09, max(0.09, 0.08) = 0.09, min(1, 0.5) → 0.5.
        let want = [0.04, 0.09, 0.09, 0.5];
        for (a, w) in adj.iter().zip(want) {
            assert!((a - w).abs() < 1e-15, "{adj:?}");
        }
        assert_eq!(holm(&[0.6, 0.7]).unwrap(), vec![1.0, 1.0]);
        assert!(holm(&[1.2]).is_err());
        assert!(holm(&[]).unwrap().is_empty());
    }

    /// Textbook exact case: n = 5 all positive → R⁺ = 15, p = 2/32.
    #[test]
    fn wilcoxon_exact_small() {
        let x = [1.0, 2.0, 3.0, 4.0, 5.0];
        let y = [0.0; 5];
        let r = wilcoxon(&x, &y, WilcoxonOptions::default()).unwrap();
        assert_eq!(r.method, WilcoxonMethod::Exact);
        assert_eq!(r.statistic, 0.0);
        assert_eq!(r.p_value, 0.0625);
        assert_eq!(r.rank_biserial, 1.0);
        assert_eq!(wilcoxon_counts(10).iter().sum::<u64>(), 1024);
    }

    #[test]
    fn wilcoxon_zero_methods_differ_as_documented() {
        let d = [
            0.0, 0.0, 1.0, -2.0, 3.0, 4.0, 5.0, 6.0, -7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0,
        ];
        let opts = |zero_method| WilcoxonOptions {
            zero_method,
            correction: false,
            method: WilcoxonMethod::Asymptotic,
        };
        let w = wilcoxon_differences(&d, opts(ZeroMethod::Wilcox)).unwrap();
        // Ranks of the 13 non-zero |d|: 1..13; negatives -2, -7 take ranks 2 and 7.
        assert_eq!((w.r_plus, w.r_minus), (82.0, 9.0));
        let p = wilcoxon_differences(&d, opts(ZeroMethod::Pratt)).unwrap();
        // Zeros take ranks 1 and 2, the rest shift by 2.
        assert_eq!((p.r_plus, p.r_minus), (82.0 + 22.0, 9.0 + 4.0));
        let z = wilcoxon_differences(&d, opts(ZeroMethod::Zsplit)).unwrap();
        assert_eq!((z.r_plus, z.r_minus), (104.0 + 1.5, 13.0 + 1.5));
        assert!(wilcoxon_differences(&[0.0, 0.0], WilcoxonOptions::default()).is_err());
    }

    #[test]
    fn spearman_perfect_and_exact() {
        let x = [1.0, 2.0, 3.0, 4.0, 5.0];
        let r = spearman(&x, &x, SpearmanMethod::ExactPermutation).unwrap();
        assert_eq!(r.rho, 1.0);
        // Only the identity reaches ρ = 1: p = 2/120.
        assert_eq!(r.p_value, 2.0 / 120.0);
        let t = spearman(&x, &x, SpearmanMethod::TApproximation).unwrap();
        assert_eq!(t.p_value, 0.0);
        assert!(spearman(&x, &[1.0; 5], SpearmanMethod::Auto).is_err());
    }

    #[test]
    fn tlx_validates() {
        assert_eq!(raw_tlx([10.0, 5.0, 15.0, 20.0, 0.0, 10.0]).unwrap(), 10.0);
        assert!(raw_tlx([21.0, 5.0, 15.0, 20.0, 0.0, 10.0]).is_err());
        assert!(raw_tlx([f64::NAN, 5.0, 15.0, 20.0, 0.0, 10.0]).is_err());
    }
}
