//! Every two variants of a sweep compared seed by seed: the mean of their paired differences,
//! its 95 % confidence interval, and on how many seeds each was lower (`paired` in
//! `table.json`, the second table of `table.md`).
//!
//! A seed fixes the world a run sees (the cars and their routes, the radio's losses), so much
//! of the spread of a metric over seeds is the world's and is shared by the variants. Taking
//! the difference seed by seed removes that part: for variants `a` and `b` (in the table's
//! column order, `a` first), a metric, and the `n` seeds on which both have a value,
//! `d_i = a_i − b_i` and
//!
//! - `mean` and `sd`: the mean and the sample standard deviation (`n − 1`) of the `d_i`;
//! - `ci95`: `mean ± t(0.975, n − 1) · sd / √n`, with Student's t quantile ([`t_quantile`]);
//! - `t`: `mean / (sd / √n)`;
//! - `a_better`, `b_better`, `ties`: the seeds on which `a`'s value is lower, `b`'s is, or
//!   they are equal.
//!
//! Lower is better for all four metrics compared (UA, OA, target-set area, localisation
//! error; `COMPARED` in [`super::metrics`]), so a negative mean favours `a`. A CI that excludes 0
//! says the difference is measurable on these seeds; one that holds 0 says these seeds cannot
//! tell the two apart (more seeds may). With one pair there is no `sd`, `ci95` or `t`; with
//! equal differences on every seed (`sd` 0) the CI is the mean and there is no `t`.
//!
//! Each metric is compared twice: on its row of the table read from `summary.json`
//! (`"final"`: UA and OA at the last step, area and error averaged over the whole run) and on
//! its mean over the steady window (`"100-300 s"`, [`super::metrics::STEADY_WINDOW_S`]).
//!
//! An axis sweep compares its values the same way, each value with the first, per variant
//! ([`super::axis`]), with the same statistics and the same Markdown.

use std::fmt::Write as _;

use serde::{Serialize, Serializer};

use super::metrics::{COMPARED, ROWS, digits, window_text};
use protocol::variant::Variant;

/// Which value of a metric a comparison is of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Window {
    /// The run's value in `summary.json` (`"final"`).
    Final,
    /// The mean over the steady window (`"100-300 s"`).
    Steady,
}

impl Window {
    /// Both, in the order they are listed.
    pub const BOTH: [Window; 2] = [Window::Final, Window::Steady];

    /// `final` or the window, e.g. `100-300 s`.
    pub fn name(self) -> String {
        match self {
            Window::Final => "final".into(),
            Window::Steady => window_text(),
        }
    }
}

impl Serialize for Window {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(&self.name())
    }
}

/// The statistics of the paired differences `a_i − b_i` of one metric.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Differences {
    /// Seeds on which both have a value.
    pub n: usize,
    /// Mean difference (`None` without a pair).
    pub mean: Option<f64>,
    /// Sample standard deviation of the differences (`None` below two pairs).
    pub sd: Option<f64>,
    /// 95 % confidence interval of the mean difference, `[low, high]`.
    pub ci95: Option<[f64; 2]>,
    /// `mean / (sd / √n)` (`None` below two pairs or when `sd` is 0).
    pub t: Option<f64>,
    /// Seeds on which `a`'s value is lower (better).
    pub a_better: usize,
    /// Seeds on which `b`'s value is lower (better).
    pub b_better: usize,
    /// Seeds on which they are equal.
    pub ties: usize,
}

impl Differences {
    /// The statistics of `a_i − b_i` over the seeds on which both have a value (`a` and `b`
    /// by seed, in the same seed order).
    pub fn of(a: &[Option<f64>], b: &[Option<f64>]) -> Differences {
        let pairs: Vec<(f64, f64)> = a
            .iter()
            .zip(b)
            .filter_map(|(a, b)| Some(((*a)?, (*b)?)))
            .collect();
        let n = pairs.len();
        let d: Vec<f64> = pairs.iter().map(|(a, b)| a - b).collect();
        let mean = (n > 0).then(|| d.iter().sum::<f64>() / n as f64);
        let sd = mean.filter(|_| n > 1).map(|m| {
            let squares: f64 = d.iter().map(|x| (x - m).powi(2)).sum();
            (squares / (n - 1) as f64).sqrt()
        });
        let (ci95, t) = match (mean, sd) {
            (Some(m), Some(sd)) => {
                let se = sd / (n as f64).sqrt();
                let half = t_quantile(0.975, (n - 1) as f64) * se;
                (Some([m - half, m + half]), (se > 0.0).then(|| m / se))
            }
            _ => (None, None),
        };
        let count = |lower: fn(f64, f64) -> bool| pairs.iter().filter(|p| lower(p.0, p.1)).count();
        Differences {
            n,
            mean,
            sd,
            ci95,
            t,
            a_better: count(|a, b| a < b),
            b_better: count(|a, b| b < a),
            ties: count(|a, b| a == b),
        }
    }
}

/// One metric compared between two sides: the part every paired comparison shares.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PairedMetric {
    /// The metric: `ua`, `oa`, `target_set_area` or `loc_error_m`.
    pub metric: &'static str,
    /// Which of its values: `final` (the table's row from `summary.json`) or the steady
    /// window's mean.
    pub window: Window,
    /// The statistics of `a − b` seed by seed, in the metric's unit (fractions of the
    /// region, metres).
    #[serde(flatten)]
    pub differences: Differences,
}

/// Two variants compared on one metric: an object of `paired` in `table.json`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Paired {
    /// The first variant (left of the other in the table).
    pub a: Variant,
    /// The second variant.
    pub b: Variant,
    /// The metric, its window and the statistics of `a − b`.
    #[serde(flatten)]
    pub compared: PairedMetric,
}

/// Every two variants of `results` (in order, `a` before `b`), on every metric of
/// [`COMPARED`], each as its final value and its window mean; `results` holds each variant's
/// runs by seed, each run as its values of the table's rows ([`ROWS`]).
pub(super) fn compare(results: &[(Variant, Vec<Vec<Option<f64>>>)]) -> Vec<Paired> {
    let column = |runs: &[Vec<Option<f64>>], key: &str| -> Option<Vec<Option<f64>>> {
        let row = ROWS.iter().position(|r| r.key == key)?;
        Some(runs.iter().map(|r| r.get(row).copied().flatten()).collect())
    };
    let mut paired = Vec::new();
    for (i, (a, a_runs)) in results.iter().enumerate() {
        for (b, b_runs) in &results[i + 1..] {
            let metrics = compare_metrics(|key| column(a_runs, key), |key| column(b_runs, key));
            paired.extend(metrics.into_iter().map(|compared| Paired {
                a: *a,
                b: *b,
                compared,
            }));
        }
    }
    paired
}

/// `a − b` on every metric of [`COMPARED`], each as its final value and then its window mean:
/// `a(key)` and `b(key)` are the values by seed (in the same seed order) of the table's row
/// `key`, `None` for a row they do not have (then that comparison is left out).
pub(super) fn compare_metrics(
    a: impl Fn(&str) -> Option<Vec<Option<f64>>>,
    b: impl Fn(&str) -> Option<Vec<Option<f64>>>,
) -> Vec<PairedMetric> {
    let mut compared = Vec::new();
    for metric in &COMPARED {
        for (window, row) in Window::BOTH.into_iter().zip(metric.rows) {
            if let (Some(a), Some(b)) = (a(row.key), b(row.key)) {
                compared.push(PairedMetric {
                    metric: metric.metric,
                    window,
                    differences: Differences::of(&a, &b),
                });
            }
        }
    }
    compared
}

/// One comparison of a paired table: two sides' differences on one metric and window.
pub(super) trait Comparison {
    /// The row's first cells, naming the sides (`paper − setfleet`); rows with the same
    /// sides and metric are one row of the table, final and window.
    fn sides(&self) -> String;
    /// The metric (a `metric` of [`COMPARED`]), its window and the differences.
    fn compared(&self) -> &PairedMetric;
}

impl Comparison for Paired {
    fn sides(&self) -> String {
        format!("{} − {}", self.a.name(), self.b.name())
    }

    fn compared(&self) -> &PairedMetric {
        &self.compared
    }
}

/// How a paired table names the two sides it compares.
pub(super) struct Sides<'a> {
    /// What the differences are, starting the table's note: `Paired differences a − b`.
    pub(super) title: &'a str,
    /// The first side, whose lower values a negative difference says.
    pub(super) a: &'a str,
    /// The second side.
    pub(super) b: &'a str,
    /// The heads of the columns [`Comparison::sides`] fills: `a − b`.
    pub(super) heads: &'a str,
}

/// The paired section of `table.md`: one row per pair and metric, the final values'
/// difference and the window means', each with its CI and who was lower how often.
pub(super) fn to_markdown(paired: &[Paired], md: &mut String) {
    let sides = Sides {
        title: "Paired differences a − b",
        a: "a",
        b: "b",
        heads: "a − b",
    };
    write_section(&sides, paired, md);
}

/// A paired section of Markdown (nothing without a comparison): a note on how to read it,
/// then one row per sides and metric (in the order of their final comparisons), the final
/// values' difference and the window means', each with its CI and who was lower how often.
pub(super) fn write_section<C: Comparison>(sides: &Sides<'_>, compared: &[C], md: &mut String) {
    if compared.is_empty() {
        return;
    }
    let Sides { title, a, b, heads } = sides;
    let window = window_text();
    let _ = writeln!(
        md,
        "\n{title}, seed by seed on the seeds both ran: mean Δ [95 % confidence interval, \
         Student's t], and on how many seeds {a} was lower / {b} was lower / they tied. Lower \
         is better for these four metrics, so Δ < 0 favours {a}; a CI that excludes 0 means \
         the difference is measurable on these seeds. Final: the row above (UA and OA at the \
         end, area and error over the whole run); {window}: the mean over that window. \
         Fractions in percentage points (pp).\n"
    );
    let _ = writeln!(
        md,
        "| {heads} | metric | Δ final [95 % CI] | {a} / {b} lower, ties | Δ {window} [95 % CI] \
         | {a} / {b} lower, ties |"
    );
    let lead = "---|".repeat(heads.split('|').count());
    let _ = writeln!(md, "|{lead}---|---:|---:|---:|---:|");
    for (c, at_end) in compared.iter().map(|c| (c, c.compared())) {
        if at_end.window != Window::Final {
            continue;
        }
        let Some(metric) = COMPARED.iter().find(|m| m.metric == at_end.metric) else {
            continue;
        };
        let names = c.sides();
        let steady = compared.iter().map(|s| (s, s.compared())).find(|(s, d)| {
            d.window == Window::Steady && d.metric == at_end.metric && s.sides() == names
        });
        let scale = metric.scale();
        let cells = |d: Option<&Differences>| match d {
            Some(d) if d.n > 0 => [format_difference(d, scale), format_counts(d)],
            _ => ["-".into(), "-".into()],
        };
        let [final_delta, final_counts] = cells(Some(&at_end.differences));
        let [steady_delta, steady_counts] = cells(steady.map(|(_, d)| &d.differences));
        let _ = writeln!(
            md,
            "| {names} | {} | {final_delta} | {final_counts} | {steady_delta} | {steady_counts} |",
            metric.label
        );
    }
}

/// "-12.06 [-17.10, -7.02]" (times `scale`), the mean alone without a CI.
fn format_difference(d: &Differences, scale: f64) -> String {
    let Some(mean) = d.mean else {
        return "-".into();
    };
    let digits = digits(mean, scale);
    let mut text = format!("{:.digits$}", mean * scale);
    if let Some([lo, hi]) = d.ci95 {
        let _ = write!(text, " [{:.digits$}, {:.digits$}]", lo * scale, hi * scale);
    }
    text
}

/// "9 / 1, 0": the seeds on which a was lower, b was, and the ties.
fn format_counts(d: &Differences) -> String {
    format!("{} / {}, {}", d.a_better, d.b_better, d.ties)
}

/// The `p` quantile of Student's t distribution with `df` degrees of freedom (`p` in (0, 1),
/// `df > 0`; NaN otherwise), e.g. `t_quantile(0.975, 9)` = 2.262157.
///
/// For `t > 0`, `P(T > t) = I_x(df/2, 1/2) / 2` with `x = df / (df + t²)`, `I` the
/// regularised incomplete beta function; the quantile solves that for `x` by bisection (`I_x`
/// grows with `x`), to the precision of an `f64`.
pub fn t_quantile(p: f64, df: f64) -> f64 {
    if !(p > 0.0 && p < 1.0 && df > 0.0) {
        return f64::NAN;
    }
    if p < 0.5 {
        return -t_quantile(1.0 - p, df);
    }
    let tail = 2.0 * (1.0 - p);
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if beta_inc(0.5 * df, 0.5, mid) < tail {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let x = 0.5 * (lo + hi);
    (df * (1.0 - x) / x).sqrt()
}

/// The regularised incomplete beta function `I_x(a, b)`, `a, b > 0`, `x` in [0, 1]: the
/// continued fraction of Numerical Recipes (§6.4), on the side of `x` where it converges
/// fast.
fn beta_inc(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let front = (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (-x).ln_1p()).exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_fraction(a, b, x) / a
    } else {
        1.0 - front * beta_fraction(b, a, 1.0 - x) / b
    }
}

/// The continued fraction of [`beta_inc`], by the modified Lentz method.
fn beta_fraction(a: f64, b: f64, x: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let guard = |v: f64| if v.abs() < TINY { TINY } else { v };
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 / guard(1.0 - qab * x / qap);
    let mut h = d;
    for m in 1..10_000 {
        let m = f64::from(m);
        let m2 = 2.0 * m;
        let even = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 / guard(1.0 + even * d);
        c = guard(1.0 + even / c);
        h *= d * c;
        let odd = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 / guard(1.0 + odd * d);
        c = guard(1.0 + odd / c);
        let step = d * c;
        h *= step;
        if (step - 1.0).abs() < 1e-16 {
            break;
        }
    }
    h
}

/// `ln Γ(x)` for `x > 0`: Lanczos' approximation (g = 7, 9 terms), relative error near 1e-15.
fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const COEFFICIENTS: [f64; 9] = [
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
    if x < 0.5 {
        // Reflection: Γ(x) Γ(1 − x) = π / sin(πx).
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut sum = COEFFICIENTS[0];
    for (i, c) in COEFFICIENTS.iter().enumerate().skip(1) {
        sum += c / (x + i as f64);
    }
    let t = x + G + 0.5;
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_t_quantile_matches_the_tables() {
        // Student's t quantiles to 6 decimals, as printed in the tables (t(0.975, 1) is
        // tan(0.475 π) exactly).
        for (p, df, t) in [
            (0.975, 1.0, 12.706205),
            (0.975, 2.0, 4.302653),
            (0.975, 3.0, 3.182446),
            (0.975, 9.0, 2.262157),
            (0.975, 29.0, 2.045230),
            (0.975, 100.0, 1.983972),
            (0.975, 1000.0, 1.962339),
            (0.95, 10.0, 1.812461),
            (0.995, 5.0, 4.032143),
            (0.9, 4.0, 1.533206),
        ] {
            let q = t_quantile(p, df);
            assert!((q - t).abs() < 5e-7, "t({p}, {df}) = {q}, not {t}");
        }
        // The normal quantile in the limit, symmetry, and no answer outside the domain.
        assert!((t_quantile(0.975, 1e7) - 1.959964).abs() < 1e-6);
        assert!((t_quantile(0.025, 9.0) + 2.262157).abs() < 5e-7);
        assert_eq!(t_quantile(0.5, 3.0), 0.0);
        assert!(t_quantile(1.0, 3.0).is_nan() && t_quantile(0.9, 0.0).is_nan());
        // ln Γ at known points: Γ(1/2) = √π, Γ(5) = 24, and ln Γ(10.5) (Python's math.lgamma).
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-13);
        assert!((ln_gamma(5.0) - 24.0_f64.ln()).abs() < 1e-13);
        assert!((ln_gamma(10.5) - 13.940_625_219_403_763).abs() < 1e-12);
    }

    #[test]
    fn paired_differences_match_a_hand_computation() {
        // Localisation errors (m) of a and b on seeds 1..=6; seed 5 has no a, seed 6 no b, so
        // the pairs are seeds 1 to 4:
        //   a = 10, 7, 12, 5;  b = 8, 7, 9, 9;  d = a − b = 2, 0, 3, −4
        //   mean = 1/4 = 0.25
        //   deviations 1.75, −0.25, 2.75, −4.25; squares 3.0625, 0.0625, 7.5625, 18.0625
        //   sum 28.75, sd = √(28.75 / 3) = 3.095695936834452
        //   se = sd / √4 = 1.547847968417226
        //   t(0.975, 3) = 3.182446305284263, half width = 3.182446305 · 1.547847968 = 4.925943:
        //   CI = [0.25 − 4.925943, 0.25 + 4.925943] = [−4.675943, 5.175943]
        //   t = 0.25 / 1.547847968 = 0.161515
        //   a lower on seed 4, b lower on seeds 1 and 3, a tie on seed 2.
        let a = [
            Some(10.0),
            Some(7.0),
            Some(12.0),
            Some(5.0),
            None,
            Some(1.0),
        ];
        let b = [Some(8.0), Some(7.0), Some(9.0), Some(9.0), Some(3.0), None];
        let d = Differences::of(&a, &b);
        assert_eq!(d.n, 4);
        assert_eq!(d.mean, Some(0.25));
        let sd = d.sd.unwrap();
        assert!((sd - 3.095_695_936_834_452).abs() < 1e-12, "{sd}");
        let se = 1.547_847_968_417_226;
        let half = 3.182_446_305_284_263 * se;
        let [lo, hi] = d.ci95.unwrap();
        assert!((lo - (0.25 - half)).abs() < 1e-6 && (hi - (0.25 + half)).abs() < 1e-6);
        assert!(
            (lo + 4.675_943).abs() < 1e-6 && (hi - 5.175_943).abs() < 1e-6,
            "{lo} {hi}"
        );
        assert!((d.t.unwrap() - 0.25 / se).abs() < 1e-12);
        assert!((d.t.unwrap() - 0.161_515).abs() < 1e-6);
        assert_eq!((d.a_better, d.b_better, d.ties), (1, 2, 1));

        // One pair: a mean, nothing more; none: nothing; equal differences: no t.
        let one = Differences::of(&[Some(1.0)], &[Some(3.0)]);
        assert_eq!(
            (one.n, one.mean, one.sd, one.ci95, one.t),
            (1, Some(-2.0), None, None, None)
        );
        assert_eq!(one.a_better, 1);
        let none = Differences::of(&[None, Some(1.0)], &[Some(1.0), None]);
        assert_eq!((none.n, none.mean, none.ci95), (0, None, None));
        let same = Differences::of(&[Some(2.0), Some(3.0)], &[Some(1.0), Some(2.0)]);
        assert_eq!(
            (same.sd, same.ci95, same.t),
            (Some(0.0), Some([1.0, 1.0]), None)
        );
    }
}
