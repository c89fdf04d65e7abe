//! Motion (work in progress).
pub mod kinematics;
pub mod math;
pub mod stepper;
