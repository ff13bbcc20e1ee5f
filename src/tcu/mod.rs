//! The virtual transmission control unit as a pure core `Tcu::step(now, inputs) -> outputs`:
//! thermal estimator (17), decoupling controller (23)–(27), strategy and safety.
