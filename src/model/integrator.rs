//! Fixed-step explicit Runge–Kutta 4 integrator, separate from the models: a model implements
//! [`OdeSystem`] (a derivative function of a state and held inputs), the integrator advances it.
//! Discrete parts of a state (mode flags, gear selectors) are carried unchanged through a step by
//! [`OdeState::axpy`]; events (stick/slip switching) are handled by the caller between steps
//! (see `powertrain::Powertrain::step`).

/// A state that RK4 can combine: `self + k·d` on the continuous part, discrete part of `self` kept.
pub trait OdeState: Copy {
    fn axpy(&self, k: f64, d: &Self) -> Self;
}

/// A continuous-time model ẋ = f(x, u).
pub trait OdeSystem {
    type State: OdeState;
    type Input;
    fn derivative(&self, x: &Self::State, u: &Self::Input) -> Self::State;
}

/// One classical RK4 step of length `h` with the inputs held constant.
#[inline]
pub(crate) fn rk4_step<S: OdeSystem>(sys: &S, x: &S::State, u: &S::Input, h: f64) -> S::State {
    rk4_step_with(x, h, |x| sys.derivative(x, u))
}

/// One classical RK4 step of length `h` of ẋ = f(x) (inputs captured by `f`).
#[inline]
pub(crate) fn rk4_step_with<X: OdeState>(x: &X, h: f64, f: impl Fn(&X) -> X) -> X {
    let k1 = f(x);
    rk4_step_from(x, &k1, h, f)
}

/// One classical RK4 step of length `h` of ẋ = f(x) whose first stage k1 = f(x) the caller has
/// already evaluated (for event detection, say): three more evaluations.
#[inline]
pub(crate) fn rk4_step_from<X: OdeState>(x: &X, k1: &X, h: f64, f: impl Fn(&X) -> X) -> X {
    let k2 = f(&x.axpy(0.5 * h, k1));
    let k3 = f(&x.axpy(0.5 * h, &k2));
    let k4 = f(&x.axpy(h, &k3));
    x.axpy(h / 6.0, k1)
        .axpy(h / 3.0, &k2)
        .axpy(h / 3.0, &k3)
        .axpy(h / 6.0, &k4)
}

/// `n` RK4 steps of length `h`.
pub fn integrate<S: OdeSystem>(sys: &S, x: &S::State, u: &S::Input, h: f64, n: usize) -> S::State {
    let mut x = *x;
    for _ in 0..n {
        x = rk4_step(sys, &x, u, h);
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Copy)]
    struct X(f64, f64);
    impl OdeState for X {
        fn axpy(&self, k: f64, d: &Self) -> Self {
            X(self.0 + k * d.0, self.1 + k * d.1)
        }
    }
    /// Harmonic oscillator ẍ = −x.
    struct Osc;
    impl OdeSystem for Osc {
        type State = X;
        type Input = ();
        fn derivative(&self, x: &X, _: &()) -> X {
            X(x.1, -x.0)
        }
    }

    #[test]
    fn fourth_order_convergence() {
        let err = |n: usize| {
            let h = 1.0 / n as f64;
            let x = integrate(&Osc, &X(1.0, 0.0), &(), h, n);
            (x.0 - 1f64.cos()).abs()
        };
        let (e1, e2) = (err(50), err(100));
        let order = (e1 / e2).log2();
        assert!((order - 4.0).abs() < 0.1, "order {order}");
        assert!(e2 < 1e-9);
    }
}
