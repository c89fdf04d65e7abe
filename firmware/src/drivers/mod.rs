//! Small device drivers over embedded-hal traits.
