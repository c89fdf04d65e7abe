//! The machine file as written: TOML tables read with `serde`, every table
//! closed (`deny_unknown_fields`), so a misspelt key is an error and never
//! silently ignored. Values here are unchecked; [`crate::check`] turns them
//! into a [`crate::Machine`] or says what is wrong.
//!
//! The keys and their units are documented in `machines/prusa-i3.toml`
//! (every key, with a comment) and in the README, "Configure your printer".

use serde::Deserialize;
use std::collections::BTreeMap;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct File {
    pub machine: MachineSection,
    pub kinematics: Option<KinematicsSection>,
    pub motion: Option<MotionSection>,
    #[serde(default)]
    pub axes: BTreeMap<String, AxisSection>,
    #[serde(default)]
    pub heaters: BTreeMap<String, HeaterSection>,
    pub fan: Option<FanSection>,
    pub display: Option<DisplaySection>,
    pub encoders: Option<EncodersSection>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineSection {
    pub name: String,
    pub kind: String,
    pub board: String,
    pub baud: u32,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KinematicsSection {
    #[serde(rename = "type")]
    pub kind: String,
    // Delta.
    pub rod_length: Option<f64>,
    pub radius: Option<f64>,
    pub nozzle_offset: Option<f64>,
    pub tower_angles: Option<[f64; 3]>,
    pub homed_height: Option<f64>,
    pub printable_radius: Option<f64>,
    pub segment_length: Option<f64>,
    // Arm.
    pub upper_arm: Option<f64>,
    pub forearm: Option<f64>,
    pub origin: Option<[f64; 2]>,
    pub joint_gear_ratio: Option<f64>,
    pub joint_pulses_per_rev: Option<f64>,
    pub home_position: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionSection {
    pub print_acceleration: f64,
    pub retract_acceleration: f64,
    pub travel_acceleration: f64,
    pub junction_deviation: f64,
    pub arc_tolerance: f64,
    pub max_step_rate: f64,
    pub homing_order: Vec<String>,
    pub homing_acceleration: f64,
    #[serde(default)]
    pub must_home: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisSection {
    pub steps_per_mm: Option<f64>,
    pub max_feed: f64,
    pub max_acceleration: f64,
    #[serde(default)]
    pub invert_direction: bool,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub home: Option<String>,
    pub homing_feed: Option<f64>,
    pub homing_backoff: Option<f64>,
    pub homing_travel: Option<f64>,
    pub endstop_triggered: Option<String>,
    pub endstop_pullup: Option<bool>,
    #[serde(default)]
    pub hard_limits: bool,
    pub step_pin: Option<PinValue>,
    pub dir_pin: Option<PinValue>,
    pub enable_pin: Option<PinValue>,
    pub min_endstop_pin: Option<PinValue>,
    pub max_endstop_pin: Option<PinValue>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeaterSection {
    pub thermistor: Option<String>,
    pub pullup_ohms: Option<f64>,
    pub sensor_pin: Option<PinValue>,
    pub output_pin: Option<PinValue>,
    pub max_temp: f64,
    pub control: String,
    pub pid: Option<[f64; 3]>,
    pub hysteresis: Option<f64>,
    pub window_ms: Option<u16>,
    pub min_slot_ms: Option<u16>,
    pub runaway_period: Option<u16>,
    pub runaway_hysteresis: Option<u8>,
    pub watch_period: Option<u16>,
    pub watch_increase: Option<u8>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FanSection {
    pub pin: PinValue,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DisplaySection {
    #[serde(rename = "type")]
    pub kind: String,
    #[serde(default = "yes")]
    pub enabled: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncodersSection {
    #[serde(rename = "type")]
    pub kind: String,
    #[serde(default = "yes")]
    pub enabled: bool,
}

fn yes() -> bool {
    true
}

/// A pin as a user writes it: an Arduino pin number (`54`), or a name
/// (`"D54"`, `"A0"`, `"PF0"`).
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum PinValue {
    Number(i64),
    Name(String),
}

impl std::fmt::Display for PinValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PinValue::Number(n) => write!(f, "{n}"),
            PinValue::Name(name) => write!(f, "\"{name}\""),
        }
    }
}
