//! One encoder-closed stepper axis as the board's tick sees it: the
//! NSE-5310 tracker, the controller and the step-rate scale, called in the
//! right order. DC servo axes use [`AxisController`] with a
//! [`QuadratureDecoder`](super::quadrature::QuadratureDecoder) and an
//! [`HBridge`](super::output::HBridge) directly (see the module docs).

use super::control::{AxisController, DriverStatus, Reference};
use super::nse5310::LinearTracker;
use super::output::{StepRate, StepperScale};
use super::AxisFault;

/// A stepper axis with a linear encoder (SPEC §1's X and Y).
#[derive(Clone, Copy, Debug)]
pub struct EncoderAxis {
    pub tracker: LinearTracker,
    pub controller: AxisController,
    pub scale: StepperScale,
}

/// One read of the encoder, as the board got it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reading {
    /// The raw 12-bit count.
    Raw(u16),
    /// The read failed (bus error, status flags).
    Failed,
}

impl EncoderAxis {
    pub const fn new(tracker: LinearTracker, controller: AxisController, scale: StepperScale) -> Self {
        Self { tracker, controller, scale }
    }

    /// The tick for this axis: feed the reading (and the debounced index
    /// edges since the last tick), run the loop, return the step rate to run
    /// until the next tick. On `Err` the stepper must stop (zero rate) and
    /// the fault is latched until [`rehome`](Self::rehome).
    pub fn tick(&mut self, reference: Reference, reading: Reading, index_edges: u8, driver: DriverStatus) -> Result<StepRate, AxisFault> {
        let measured = match reading {
            Reading::Raw(raw) => self.tracker.update(raw, index_edges, reference.position),
            Reading::Failed => self.tracker.read_failed().map(|()| self.tracker.position()),
        };
        let velocity = self.controller.tick(reference, measured, driver)?;
        Ok(self.scale.step_rate(velocity))
    }

    /// Where the encoder says the axis is (units from the homing zero).
    pub fn measured(&self) -> i32 {
        self.tracker.position()
    }

    /// Homing finished (or `G92`): the encoder reads `position` here, the
    /// loop forgets its past and any latched fault is cleared.
    pub fn rehome(&mut self, position: i32) {
        self.tracker.set_position(position, position);
        self.controller.reset();
    }
}
