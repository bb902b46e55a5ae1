//! The One-Euro filter (Casiez, Roussel and Vogel, CHI 2012), used on hand positions (§7).
//!
//! Per sample with interval Δt [s]:
//! - α(f_c) = 1 / (1 + τ/Δt) with τ = 1 / (2π f_c);
//! - the derivative estimate ẋ = (x − x̂_prev)/Δt is low-passed with α(d_cutoff);
//! - the cutoff f_c = min_cutoff + β·|ẋ̂|, and x̂ = α(f_c)·x + (1 − α(f_c))·x̂_prev.
//!
//! The derivative uses the previous *filtered* value, as in the paper's pseudo-code. The first
//! sample initialises x̂ = x and ẋ̂ = 0.

use crate::config::OneEuroConfig;

/// Smoothing factor of a first-order low-pass with cutoff `cutoff_hz` [Hz] for interval `dt` [s].
pub fn alpha(cutoff_hz: f64, dt: f64) -> f64 {
    // 1 / (1 + τ/Δt) with τ = 1/(2π f_c), written with a single division.
    let w = 2.0 * std::f64::consts::PI * cutoff_hz * dt;
    w / (w + 1.0)
}

/// A scalar One-Euro filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OneEuro {
    params: OneEuroConfig,
    x_hat: f64,
    dx_hat: f64,
    initialised: bool,
}

impl OneEuro {
    /// A filter waiting for its first sample.
    pub fn new(params: OneEuroConfig) -> Self {
        Self {
            params,
            x_hat: 0.0,
            dx_hat: 0.0,
            initialised: false,
        }
    }

    /// Forget the state: the next sample re-initialises the filter.
    pub fn reset(&mut self) {
        self.initialised = false;
    }

    /// Whether a sample has initialised the filter since the last reset.
    pub fn is_initialised(&self) -> bool {
        self.initialised
    }

    /// The last filtered value.
    pub fn value(&self) -> f64 {
        self.x_hat
    }

    /// Filter sample `x` taken `dt` [s] after the previous one (ignored for the first sample;
    /// must be > 0 otherwise) and return the filtered value.
    pub fn filter(&mut self, x: f64, dt: f64) -> f64 {
        if !self.initialised {
            self.x_hat = x;
            self.dx_hat = 0.0;
            self.initialised = true;
            return x;
        }
        let dx = (x - self.x_hat) / dt;
        let a_d = alpha(self.params.d_cutoff_hz, dt);
        self.dx_hat = a_d * dx + (1.0 - a_d) * self.dx_hat;
        let cutoff = self.params.min_cutoff_hz + self.params.beta * self.dx_hat.abs();
        let a = alpha(cutoff, dt);
        self.x_hat = a * x + (1.0 - a) * self.x_hat;
        self.x_hat
    }
}

/// Three independent One-Euro filters, one per axis of a position, sharing the per-sample work
/// that does not depend on the axis (1/Δt and the derivative filter's α). Same arithmetic as
/// three [`OneEuro`]s, to rounding.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OneEuro3 {
    params: OneEuroConfig,
    x_hat: [f64; 3],
    dx_hat: [f64; 3],
    initialised: bool,
}

impl OneEuro3 {
    /// A filter waiting for its first sample.
    pub fn new(params: OneEuroConfig) -> Self {
        Self {
            params,
            x_hat: [0.0; 3],
            dx_hat: [0.0; 3],
            initialised: false,
        }
    }

    /// Forget the state: the next sample re-initialises the filter.
    pub fn reset(&mut self) {
        self.initialised = false;
    }

    /// Whether a sample has initialised the filter since the last reset.
    pub fn is_initialised(&self) -> bool {
        self.initialised
    }

    /// The last filtered value.
    pub fn value(&self) -> [f64; 3] {
        self.x_hat
    }

    /// Filter sample `x` taken `dt` [s] after the previous one (ignored for the first sample;
    /// must be > 0 otherwise) and return the filtered value.
    pub fn filter(&mut self, x: [f64; 3], dt: f64) -> [f64; 3] {
        if !self.initialised {
            self.x_hat = x;
            self.dx_hat = [0.0; 3];
            self.initialised = true;
            return x;
        }
        let two_pi_dt = 2.0 * std::f64::consts::PI * dt;
        let inv_dt = 1.0 / dt;
        let w_d = two_pi_dt * self.params.d_cutoff_hz;
        let a_d = w_d / (w_d + 1.0);
        for ((x, x_hat), dx_hat) in x.iter().zip(&mut self.x_hat).zip(&mut self.dx_hat) {
            let dx = (x - *x_hat) * inv_dt;
            *dx_hat = a_d * dx + (1.0 - a_d) * *dx_hat;
            let cutoff = self.params.min_cutoff_hz + self.params.beta * dx_hat.abs();
            let w = two_pi_dt * cutoff;
            let a = w / (w + 1.0);
            *x_hat = a * x + (1.0 - a) * *x_hat;
        }
        self.x_hat
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_euro_worked_example() {
        // Hand arithmetic, min_cutoff 1 Hz, beta 0.05, d_cutoff 1 Hz, dt = 0.1 s:
        //   tau(1 Hz) = 1/(2π) = 0.159154943; α(1 Hz, 0.1) = 1/(1 + 1.59154943) = 0.385869545.
        // Sample 1: x = 0 → x̂ = 0, ẋ̂ = 0.
        // Sample 2: x = 1 → ẋ = (1 − 0)/0.1 = 10; ẋ̂ = 0.385869545·10 = 3.85869545;
        //   f_c = 1 + 0.05·3.85869545 = 1.192934773 Hz; τ = 1/(2π·1.192934773) = 0.133414623;
        //   α = 1/(1 + 1.33414623) = 0.428422173; x̂ = α·1 + (1 − α)·0 = 0.428422173.
        let mut f = OneEuro::new(OneEuroConfig::default());
        assert_eq!(f.filter(0.0, 0.1), 0.0);
        let a1 = alpha(1.0, 0.1);
        assert!((a1 - 0.385869545).abs() < 1e-9);
        let y = f.filter(1.0, 0.1);
        assert!((y - 0.428422173).abs() < 1e-9, "{y}");
    }

    #[test]
    fn vector_filter_equals_three_scalar_filters() {
        let cfg = OneEuroConfig::default();
        let mut v = OneEuro3::new(cfg);
        let mut s = [OneEuro::new(cfg); 3];
        let mut t_prev = 0.0;
        for k in 0..500 {
            // Irregular intervals and a wiggly 3-D path.
            let t = k as f64 * 0.03 + 0.005 * ((k * 7) % 5) as f64;
            let x = [(t * 3.0).sin(), (t * 1.3).cos() * 0.2, t * 0.05];
            let dt = t - t_prev;
            t_prev = t;
            let y = v.filter(x, dt);
            for a in 0..3 {
                let z = s[a].filter(x[a], dt);
                assert!((y[a] - z).abs() < 1e-12, "k {k} axis {a}: {} vs {z}", y[a]);
            }
        }
    }

    #[test]
    fn constant_input_is_a_fixed_point() {
        let mut f = OneEuro::new(OneEuroConfig::default());
        for _ in 0..100 {
            assert_eq!(f.filter(0.25, 1.0 / 30.0), 0.25);
        }
    }
}
