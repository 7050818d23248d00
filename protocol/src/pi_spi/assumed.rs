//! The layouts seed 004 names but does not define (`SensorData`, `QuaternionData`, `MotorPidSettings`,
//! `KinematicsConfig`): defined here, in one place, to be aligned with the real `pi_buffer.h`.
//!
//! Everything else in [`super`] follows the seed exactly; only these four layouts are our
//! assumption. If the shared header differs, change the field lists here (and their `LEN`); the
//! const assertions in [`super`] then recompute and check the buffer sizes and offsets.
//!
//! ```text
//!  SensorData      13 B  f32 x | f32 y | f32 z | i8 accuracy (0 least … 3 most accurate)
//!                        (the seed describes these fields; their order is our assumption)
//!  QuaternionData  16 B  f32 w | f32 x | f32 y | f32 z
//!  MotorPidSettings 48 B f32 kp[4] | f32 ki[4] | f32 kd[4]          (per motor; applied to the
//!                        velocity or the position controllers by update bit 0 or 1)
//!  KinematicsConfig 64 B f32 inverse[3][4] (row-major: vx, vy, wz rows × 4 wheels) | f32 ticks_to_rad[4]
//! ```

use crate::le;

/// A 3-axis IMU reading with its MPL accuracy level.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct SensorData {
    /// x component.
    pub x: f32,
    /// y component.
    pub y: f32,
    /// z component.
    pub z: f32,
    /// InvenSense MPL accuracy, 0 (least) … 3 (most).
    pub accuracy: i8,
}

/// The DMP 6-axis orientation quaternion.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct QuaternionData {
    /// Scalar part.
    pub w: f32,
    /// x.
    pub x: f32,
    /// y.
    pub y: f32,
    /// z.
    pub z: f32,
}

/// PID gains for the four motors.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct MotorPidSettings {
    /// Proportional gains, motors 0–3.
    pub kp: [f32; 4],
    /// Integral gains.
    pub ki: [f32; 4],
    /// Derivative gains.
    pub kd: [f32; 4],
}

/// Wheel geometry for odometry: body twist from wheel speeds, and encoder scaling.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct KinematicsConfig {
    /// Rows vx, vy, wz; columns wheels 0–3: body twist = inverse × wheel speeds (rad/s).
    pub inverse: [[f32; 4]; 3],
    /// Radians per BEMF tick, wheels 0–3.
    pub ticks_to_rad: [f32; 4],
}

/// A packed little-endian layout.
pub(crate) trait Packed: Sized {
    /// Bytes on the wire.
    const LEN: usize;
    /// Writes the fields in order.
    fn write(&self, w: &mut le::Writer<'_>);
    /// Reads the fields in order.
    fn read(r: &mut le::Reader<'_>) -> Result<Self, le::Short>;
}

impl Packed for SensorData {
    const LEN: usize = 13;
    fn write(&self, w: &mut le::Writer<'_>) {
        w.f32(self.x);
        w.f32(self.y);
        w.f32(self.z);
        w.i8(self.accuracy);
    }
    fn read(r: &mut le::Reader<'_>) -> Result<Self, le::Short> {
        Ok(Self {
            x: r.f32()?,
            y: r.f32()?,
            z: r.f32()?,
            accuracy: r.i8()?,
        })
    }
}

impl Packed for QuaternionData {
    const LEN: usize = 16;
    fn write(&self, w: &mut le::Writer<'_>) {
        w.each(&[self.w, self.x, self.y, self.z], le::Writer::f32);
    }
    fn read(r: &mut le::Reader<'_>) -> Result<Self, le::Short> {
        Ok(Self {
            w: r.f32()?,
            x: r.f32()?,
            y: r.f32()?,
            z: r.f32()?,
        })
    }
}

impl Packed for MotorPidSettings {
    const LEN: usize = 48;
    fn write(&self, w: &mut le::Writer<'_>) {
        w.each(&self.kp, le::Writer::f32);
        w.each(&self.ki, le::Writer::f32);
        w.each(&self.kd, le::Writer::f32);
    }
    fn read(r: &mut le::Reader<'_>) -> Result<Self, le::Short> {
        Ok(Self {
            kp: read_f32x4(r)?,
            ki: read_f32x4(r)?,
            kd: read_f32x4(r)?,
        })
    }
}

impl Packed for KinematicsConfig {
    const LEN: usize = 64;
    fn write(&self, w: &mut le::Writer<'_>) {
        for row in &self.inverse {
            w.each(row, le::Writer::f32);
        }
        w.each(&self.ticks_to_rad, le::Writer::f32);
    }
    fn read(r: &mut le::Reader<'_>) -> Result<Self, le::Short> {
        Ok(Self {
            inverse: [read_f32x4(r)?, read_f32x4(r)?, read_f32x4(r)?],
            ticks_to_rad: read_f32x4(r)?,
        })
    }
}

pub(crate) fn read_f32x4(r: &mut le::Reader<'_>) -> Result<[f32; 4], le::Short> {
    Ok([r.f32()?, r.f32()?, r.f32()?, r.f32()?])
}
