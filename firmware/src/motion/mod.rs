//! Motion (work in progress).
pub mod kinematics;
pub mod math;
