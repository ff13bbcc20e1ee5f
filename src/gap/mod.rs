//! Sim-to-real gap diagnosis: datasets, residuals per subsystem, effect fitting, reports.
