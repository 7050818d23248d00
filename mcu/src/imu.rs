//! The seed 004 board's IMU fusion: MPU6050 raw readings → the `ImuData` of the next `TxBuffer`.
//!
//! ```text
//!  called from                      body                        what it does
//!  the IMU read, once per period    ImuFusion::update           registers → bias, orientation → Madgwick step → ImuData
//!                                   ImuFusion::sensor_lost      no answer this period → ImuData, every accuracy 0
//!  a frame with IMU_ORIENTATION     ImuFusion::set_orientation  the Pi's 3×3 matrices, refused unless rotations
//! ```
//!
//! # The filter
//!
//! Madgwick's gradient-descent attitude filter from the `ahrs` crate (0.8, MIT, `default-features =
//! false`: no_std, built on `nalgebra` with `libm`). Chosen over `imu-fusion` (a port of the same
//! author's later Fusion library, but on the older nalgebra 0.32 and with a much larger API we would
//! not use) and `dcmimu` (a DCM/Kalman filter, not Madgwick or Mahony): `ahrs` is a small
//! implementation of the two filters whose latest release follows the current nalgebra, its
//! dependency tree is nalgebra's no_std core (approx, num-traits/-complex/-rational, simba, typenum,
//! libm) and nothing else, and it builds for `thumbv7em-none-eabihf`. Madgwick over `ahrs`'s Mahony: one gain instead of two, and Mahony's
//! integral term would only duplicate the start-up bias estimate below (with no magnetometer neither
//! filter can observe a yaw bias).
//!
//! Frames: the *sensor* frame is the MPU6050's axes; the *board* frame is the sensor frame mapped by
//! the gyro orientation matrix ([`ImuFusion::set_orientation`], identity at power-on; the
//! accelerometer shares the gyroscope's die, so the same matrix maps both); the *world* frame has
//! z up (against gravity), x along the board's x axis as it was at power-on, levelled, and y
//! completing a right-handed frame (to the left of x). The filter's quaternion `q` maps board
//! vectors to world vectors (`v_world = q · v_board · q*`).
//!
//! Start-up, and the gain: the first `sample_hz` readings in a row (one second) with a still sensor
//! (every gyro axis within [`STILL_GYRO_SPAN`] counts peak to peak, every accelerometer axis within
//! [`STILL_ACCEL_SPAN`], the acceleration's magnitude within 1 g ± 10 %) give the gyro bias, their
//! mean, if within ±[`MAX_BIAS_DPS`] °/s. Any other reading restarts the window (counted). Until the
//! bias is known, the filter uses the start-up gain [`BETA_STARTUP`], which finds the tilt from
//! gravity within about a second, then [`BETA`]. A board that turns at a constant rate during the
//! whole start-up window is taken as still: the bias then holds that rate. The board is expected to
//! stand still at power-on.
//!
//! A reading whose acceleration cannot stand for gravity (an axis saturated, or a magnitude outside
//! 0.5 g … 1.5 g) steps the filter with the gyroscope alone (counted in `accel_rejected`).
//!
//! # `ImuData`, field by field
//!
//! | field            | content                                                                           | accuracy |
//! |------------------|-----------------------------------------------------------------------------------|----------|
//! | `gyro`           | angular velocity, rad/s, world frame (bias removed, then rotated by `q`)          | min(gyro, attitude) |
//! | `accel`          | specific force (what the accelerometer measures: +g upward at rest), m/s², world frame | min(accel, attitude) |
//! | `compass`        | zeros: the MPU6050 has no magnetometer                                            | 0 |
//! | `linear_accel`   | `accel` minus (0, 0, g): gravity removed with the fused attitude, m/s², world frame | min(accel, attitude) |
//! | `accel_velocity` | zeros: integrating `linear_accel` without a velocity reference drifts without bound | 0 |
//! | `dmp_quat`       | the Madgwick filter's `q` (w, x, y, z), unit norm, w ≥ 0; *not* the InvenSense DMP's quaternion | — |
//! | `heading`        | degrees in [0, 360), clockwise seen from above, from the *power-on* heading (no magnetometer: north is unknown, so "north" is where the board's x axis pointed at power-on) | — |
//! | `temperature`    | die temperature, °C: `raw / 340 + 36.53` (MPU6050 register map)                   | — |
//!
//! Board-frame values are recovered on the Pi by rotating with the conjugate of `dmp_quat`.
//!
//! # Accuracy rules (0 = least … 3 = most, the MPL's levels)
//!
//! | level of      | 0                             | 1                          | 2                  | 3 |
//! |---------------|-------------------------------|----------------------------|--------------------|---|
//! | gyro          | bias not yet estimated        | an axis saturated (±250 °/s exceeded: rate clipped) | — | bias known, no axis saturated |
//! | accel         | —                             | an axis saturated (±2 g exceeded)  | — | no axis saturated |
//! | attitude      | bias not yet estimated, or the sensor was lost since the last judgement | measured gravity ≥ 10° off the filter's | 2° … 10° off | < 2° off |
//!
//! The attitude level is judged on quasi-static readings only (acceleration magnitude within
//! 1 g ± 10 %, not saturated): on others the filter's gravity cannot be compared with the
//! measurement, and the level stays as last judged. Nothing non-finite is sent: a vector that
//! would not be finite goes as zeros with accuracy 0, a quaternion as the last one, a heading or a
//! temperature as 0 (each counted in `non_finite`), and a filter step that would leave a
//! non-finite quaternion is undone (counted too).
//!
//! # A lost reading ([`ImuFusion::sensor_lost`])
//!
//! The measured vectors (`gyro`, `accel`, `linear_accel`) are zeros, since nothing was measured; the
//! estimates (`dmp_quat`, `heading`, `temperature`) are the last ones (identity, 0 and 0 before the
//! first reading); every accuracy is 0. The filter is not stepped, so a rotation during the lost
//! period is missing from the heading for good; the tilt is found again from gravity, which is why
//! the attitude level drops to 0 until the next quasi-static reading judges it.

use crate::cdc::IMU_SCALE;
use ahrs::{Ahrs, Madgwick};
use nalgebra::{ComplexField, RealField, Rotation3, UnitQuaternion, Vector3};
use protocol::pi_spi::assumed::{QuaternionData, SensorData};
use protocol::pi_spi::ImuData;

/// Standard gravity, m/s².
pub const G: f32 = 9.806_65;
/// Madgwick gain after start-up: the tilt is corrected at up to 2·β rad/s (here about 6 °/s), slowly
/// enough that the linear accelerations of a driving robot tilt the estimate little.
pub const BETA: f32 = 0.05;
/// Madgwick gain while the gyro bias is being estimated: up to 2 rad/s of tilt correction, so the
/// tilt is found from gravity within about a second.
pub const BETA_STARTUP: f32 = 1.0;
/// Largest peak-to-peak gyro reading per axis, counts, within a still start-up window (2 °/s at ±250 °/s).
pub const STILL_GYRO_SPAN: i32 = 262;
/// Largest peak-to-peak accelerometer reading per axis, counts, within a still window (0.05 g at ±2 g).
pub const STILL_ACCEL_SPAN: i32 = 819;
/// Largest gyro bias accepted, °/s per axis (the MPU6050's zero-rate tolerance is ±20 °/s).
pub const MAX_BIAS_DPS: i32 = 30;
/// Accuracy level: the most accurate.
pub const ACCURACY_BEST: i8 = 3;

/// cos 2°: the attitude is "settled" (level 3) when measured and estimated gravity are closer.
const COS_2_DEG: f32 = 0.999_390_8;
/// cos 10°: level 2 down to here.
const COS_10_DEG: f32 = 0.984_807_8;
const IDENTITY: [i8; 9] = [1, 0, 0, 0, 1, 0, 0, 0, 1];

/// Why an orientation matrix pair was refused (nothing changed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum OrientationError {
    /// The gyro matrix has an entry other than −1, 0, +1.
    GyroEntry = 1,
    /// A row or column of the gyro matrix has not exactly one nonzero entry.
    GyroNotPermutation = 2,
    /// The gyro matrix is a reflection (determinant −1), not a rotation.
    GyroReflection = 3,
    /// The compass matrix has an entry other than −1, 0, +1.
    CompassEntry = 4,
    /// A row or column of the compass matrix has not exactly one nonzero entry.
    CompassNotPermutation = 5,
    /// The compass matrix is a reflection (determinant −1), not a rotation.
    CompassReflection = 6,
}

/// What a matrix is wrong with (see [`check_rotation`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MatrixDefect {
    /// An entry other than −1, 0, +1.
    Entry,
    /// A row or column without exactly one nonzero entry.
    NotPermutation,
    /// Determinant −1.
    Reflection,
}

/// Checks that a row-major 3×3 matrix is a signed permutation with determinant +1 (one of the 24
/// rotations that map axes onto axes).
///
/// The determinant of a signed permutation is the permutation's sign times the product of the
/// signs: +1 exactly when the permutation is even and the number of −1 entries is even, or both odd.
//
// By index over the nine entries (row r, column c at 3·r + c < 9): under Kani no slice iterator,
// whose every step it models as a checked pointer offset.
#[allow(
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::needless_range_loop
)]
pub fn check_rotation(m: [i8; 9]) -> Result<(), MatrixDefect> {
    for i in 0..9 {
        if !(-1..=1).contains(&m[i]) {
            return Err(MatrixDefect::Entry);
        }
    }
    // Nonzero entries per row and per column (at most 3 each); row r's last nonzero entry is in
    // column perm[r], its only one once the counts are all 1.
    let mut per_row = [0u8; 3];
    let mut per_column = [0u8; 3];
    let mut perm = [0usize; 3];
    let mut negatives = 0u8;
    for r in 0..3 {
        for c in 0..3 {
            let v = m[3 * r + c];
            if v != 0 {
                per_row[r] += 1;
                per_column[c] += 1;
                perm[r] = c;
            }
            if v < 0 {
                negatives += 1;
            }
        }
    }
    if per_row != [1; 3] || per_column != [1; 3] {
        return Err(MatrixDefect::NotPermutation);
    }
    let even_perm = matches!(perm, [0, 1, 2] | [1, 2, 0] | [2, 0, 1]);
    let even_negatives = negatives & 1 == 0;
    if even_perm != even_negatives {
        return Err(MatrixDefect::Reflection);
    }
    Ok(())
}

/// What the fusion counted since power-on (all saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ImuCounters {
    /// Readings given to [`ImuFusion::update`].
    pub readings: u32,
    /// Periods the sensor did not answer ([`ImuFusion::sensor_lost`]).
    pub lost: u32,
    /// Readings with an accelerometer axis at the ±2 g limit.
    pub accel_saturated: u32,
    /// Readings with a gyroscope axis at the ±250 °/s limit.
    pub gyro_saturated: u32,
    /// Readings whose acceleration could not stand for gravity: the filter stepped on the gyro alone.
    pub accel_rejected: u32,
    /// Non-finite values caught: a filter step or orientation turn undone, or a field replaced.
    pub non_finite: u32,
    /// Start-up bias windows restarted because the sensor was not still.
    pub bias_restarts: u32,
    /// Orientation matrix pairs refused.
    pub orientation_refused: u32,
}

/// The start-up gyro-bias window: sums, and each axis's range, over consecutive still readings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct BiasWindow {
    count: u32,
    sum: [i64; 3],
    gyro_min: [i16; 3],
    gyro_max: [i16; 3],
    accel_min: [i16; 3],
    accel_max: [i16; 3],
}

impl BiasWindow {
    const fn start(accel: [i16; 3], gyro: [i16; 3]) -> Self {
        Self {
            count: 1,
            sum: [gyro[0] as i64, gyro[1] as i64, gyro[2] as i64],
            gyro_min: gyro,
            gyro_max: gyro,
            accel_min: accel,
            accel_max: accel,
        }
    }

    /// Adds a reading; false if the window is then no longer still (the caller restarts it).
    fn add(&mut self, accel: [i16; 3], gyro: [i16; 3]) -> bool {
        fn widen(min: &mut [i16; 3], max: &mut [i16; 3], v: [i16; 3], span: i32) -> bool {
            let mut ok = true;
            for ((lo, hi), x) in min.iter_mut().zip(max.iter_mut()).zip(v) {
                *lo = (*lo).min(x);
                *hi = (*hi).max(x);
                ok &= i32::from(*hi).saturating_sub(i32::from(*lo)) <= span;
            }
            ok
        }
        let g_ok = widen(
            &mut self.gyro_min,
            &mut self.gyro_max,
            gyro,
            STILL_GYRO_SPAN,
        );
        let a_ok = widen(
            &mut self.accel_min,
            &mut self.accel_max,
            accel,
            STILL_ACCEL_SPAN,
        );
        for (s, x) in self.sum.iter_mut().zip(gyro) {
            *s = s.saturating_add(i64::from(x));
        }
        self.count = self.count.saturating_add(1);
        g_ok && a_ok
    }

    /// The mean gyro reading, counts, if every axis is within ±[`MAX_BIAS_DPS`].
    fn mean(&self) -> Option<[f32; 3]> {
        let n = i64::from(self.count.max(1));
        let limit = i64::from(MAX_BIAS_DPS.saturating_mul(IMU_SCALE.gyro_lsb_per_10dps) / 10);
        let mut out = [0.0f32; 3];
        for (o, s) in out.iter_mut().zip(self.sum) {
            let m = s.checked_div(n).unwrap_or(0);
            if m.saturating_abs() > limit {
                return None;
            }
            // The exact mean (not the truncated `m`), as a float.
            *o = s as f32 / n as f32;
        }
        Some(out)
    }
}

/// The IMU fusion of the seed 004 board: gyro bias, orientation, Madgwick filter, `ImuData`.
#[derive(Clone, Debug)]
pub struct ImuFusion {
    filter: Madgwick<f32>,
    dt: f32,
    /// Start-up window length, readings (`sample_hz`, at least 1).
    window_len: u32,
    window: Option<BiasWindow>,
    /// Gyro bias in sensor counts, once estimated.
    bias: Option<[f32; 3]>,
    gyro_orientation: [i8; 9],
    compass_orientation: [i8; 9],
    attitude_level: i8,
    last: ImuData,
    counters: ImuCounters,
}

impl ImuFusion {
    /// A fusion for readings at `sample_hz` (0 is taken as 1): identity orientations, attitude
    /// level 0, the start-up bias window empty.
    pub fn new(sample_hz: u32) -> Self {
        let hz = sample_hz.max(1);
        let dt = 1.0 / hz as f32;
        Self {
            filter: Madgwick::new(dt, BETA_STARTUP),
            dt,
            window_len: hz,
            window: None,
            bias: None,
            gyro_orientation: IDENTITY,
            compass_orientation: IDENTITY,
            attitude_level: 0,
            last: ImuData {
                dmp_quat: QuaternionData {
                    w: 1.0,
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                },
                ..ImuData::default()
            },
            counters: ImuCounters::default(),
        }
    }

    /// What happened since power-on.
    pub const fn counters(&self) -> &ImuCounters {
        &self.counters
    }

    /// True once the start-up gyro bias is known.
    pub const fn bias_ready(&self) -> bool {
        self.bias.is_some()
    }

    /// The attitude accuracy level (see the module documentation).
    pub const fn attitude_level(&self) -> i8 {
        self.attitude_level
    }

    /// The orientation matrices in use (gyro, compass), row-major.
    pub const fn orientation(&self) -> ([i8; 9], [i8; 9]) {
        (self.gyro_orientation, self.compass_orientation)
    }

    /// Seed update flag `IMU_ORIENTATION`: row-major 3×3 matrices mapping sensor axes to board axes
    /// (`board = M · sensor`). Only signed permutation matrices with determinant +1 are accepted;
    /// otherwise `Err` (the gyro matrix is checked first) and nothing changes. The gyro matrix
    /// maps the gyroscope and the accelerometer. The compass matrix is checked and kept, and used by
    /// nothing: this board has no magnetometer.
    ///
    /// The world frame stays where it was: the filter's quaternion is turned with the new board
    /// axes, so the world-frame vectors go on without a jump, and the heading becomes that of the
    /// new board x axis.
    pub fn set_orientation(
        &mut self,
        gyro: [i8; 9],
        compass: [i8; 9],
    ) -> Result<(), OrientationError> {
        let checked = match (check_rotation(gyro), check_rotation(compass)) {
            (Err(d), _) => Err(match d {
                MatrixDefect::Entry => OrientationError::GyroEntry,
                MatrixDefect::NotPermutation => OrientationError::GyroNotPermutation,
                MatrixDefect::Reflection => OrientationError::GyroReflection,
            }),
            (Ok(()), Err(d)) => Err(match d {
                MatrixDefect::Entry => OrientationError::CompassEntry,
                MatrixDefect::NotPermutation => OrientationError::CompassNotPermutation,
                MatrixDefect::Reflection => OrientationError::CompassReflection,
            }),
            (Ok(()), Ok(())) => Ok(()),
        };
        if let Err(e) = checked {
            self.counters.orientation_refused = self.counters.orientation_refused.saturating_add(1);
            return Err(e);
        }
        if gyro != self.gyro_orientation {
            // v_world = R(q) · M_old · s = R(q') · M_new · s  ⇒  R(q') = R(q) · M_old · M_newᵀ.
            let turn = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
                ops::change_of_axes(self.gyro_orientation, gyro),
            ));
            let q = ops::compose(&self.filter.quat, &turn);
            if finite_quat(&q) {
                self.filter.quat = q;
            } else {
                self.count_non_finite();
            }
            self.gyro_orientation = gyro;
        }
        self.compass_orientation = compass;
        Ok(())
    }

    /// One reading at `sample_hz`: accelerometer and gyroscope counts (sensor axes, ±2 g and
    /// ±250 °/s full scale) and the raw temperature. Returns the `ImuData` for the next `TxBuffer`.
    pub fn update(&mut self, accel: [i16; 3], gyro: [i16; 3], temp_raw: i16) -> ImuData {
        let c = &mut self.counters;
        c.readings = c.readings.saturating_add(1);
        let accel_sat = accel.iter().any(|&v| v == i16::MIN || v == i16::MAX);
        let gyro_sat = gyro.iter().any(|&v| v == i16::MIN || v == i16::MAX);
        if accel_sat {
            c.accel_saturated = c.accel_saturated.saturating_add(1);
        }
        if gyro_sat {
            c.gyro_saturated = c.gyro_saturated.saturating_add(1);
        }

        self.track_bias(accel, gyro);
        let bias = self.bias.or_else(|| self.window.and_then(|w| w.mean()));
        let [bx, by, bz] = bias.unwrap_or([0.0; 3]);
        let [gx, gy, gz] = gyro.map(f32::from);
        let gyro_s = Vector3::new(gx - bx, gy - by, gz - bz);
        let accel_s = Vector3::from(accel.map(f32::from));
        let gyro_b = ops::rotate(self.gyro_orientation, &gyro_s, RAD_S_PER_LSB);
        let accel_b = ops::rotate(self.gyro_orientation, &accel_s, MS2_PER_LSB);

        // Can the acceleration stand for gravity?
        let norm_g = accel_b.norm() / G;
        let usable = !accel_sat && (0.5..=1.5).contains(&norm_g);
        let quasi_static = !accel_sat && (0.9..=1.1).contains(&norm_g);
        let before = self.filter.quat;
        let stepped = if usable {
            self.filter.update_imu(&gyro_b, &accel_b).is_ok()
        } else {
            false
        };
        if !stepped {
            self.counters.accel_rejected = self.counters.accel_rejected.saturating_add(1);
            self.filter.update_gyro(&gyro_b);
        }
        if !finite_quat(&self.filter.quat) {
            self.filter.quat = before;
            self.count_non_finite();
        }
        let q = self.filter.quat;

        if self.bias.is_none() {
            self.attitude_level = 0;
        } else if quasi_static {
            // Gravity as the filter expects to measure it, against gravity as measured.
            let expected = q.inverse_transform_vector(&Vector3::z());
            let cos = expected.dot(&accel_b) / accel_b.norm();
            self.attitude_level = if cos > COS_2_DEG {
                3
            } else if cos > COS_10_DEG {
                2
            } else {
                1
            };
        }

        let gyro_level = match (self.bias.is_some(), gyro_sat) {
            (false, _) => 0,
            (true, true) => 1,
            (true, false) => ACCURACY_BEST,
        };
        let accel_level = if accel_sat { 1 } else { ACCURACY_BEST };
        let att = self.attitude_level;
        let accel_w = q.transform_vector(&accel_b);
        let out = ImuData {
            gyro: sensor(q.transform_vector(&gyro_b), gyro_level.min(att)),
            accel: sensor(accel_w, accel_level.min(att)),
            compass: SensorData::default(),
            linear_accel: sensor(ops::minus_gravity(&accel_w), accel_level.min(att)),
            accel_velocity: SensorData::default(),
            dmp_quat: quat_data(&q),
            heading: heading_deg(&q),
            temperature: f32::from(temp_raw) / 340.0 + 36.53,
        };
        let out = self.guard(out);
        self.last = out;
        out
    }

    /// The sensor did not answer this period: zeros for the measured vectors, the last quaternion,
    /// heading and temperature, every accuracy 0 (see the module documentation).
    pub fn sensor_lost(&mut self) -> ImuData {
        self.counters.lost = self.counters.lost.saturating_add(1);
        self.attitude_level = 0;
        ImuData {
            gyro: SensorData::default(),
            accel: SensorData::default(),
            compass: SensorData::default(),
            linear_accel: SensorData::default(),
            accel_velocity: SensorData::default(),
            dmp_quat: self.last.dmp_quat,
            heading: self.last.heading,
            temperature: self.last.temperature,
        }
    }

    /// The start-up window: restarted by a reading that is not still, closed after `window_len`.
    fn track_bias(&mut self, accel: [i16; 3], gyro: [i16; 3]) {
        if self.bias.is_some() {
            return;
        }
        let one_g = IMU_SCALE.accel_lsb_per_g as f32;
        let [ax, ay, az] = accel.map(f32::from);
        let norm = ComplexField::sqrt(ax * ax + ay * ay + az * az) / one_g;
        let level = (0.9..=1.1).contains(&norm);
        let still = match self.window.as_mut() {
            Some(w) => w.add(accel, gyro) && level,
            None => level,
        };
        if !still {
            if self.window.is_some() {
                self.counters.bias_restarts = self.counters.bias_restarts.saturating_add(1);
            }
            self.window = level.then(|| BiasWindow::start(accel, gyro));
            return;
        }
        let w = self
            .window
            .get_or_insert_with(|| BiasWindow::start(accel, gyro));
        if w.count >= self.window_len {
            match w.mean() {
                Some(b) => {
                    self.bias = Some(b);
                    self.window = None;
                    self.filter = Madgwick::new_with_quat(self.dt, BETA, self.filter.quat);
                }
                None => {
                    // Still, but a bias beyond the sensor's tolerance: not believed; start again.
                    self.counters.bias_restarts = self.counters.bias_restarts.saturating_add(1);
                    self.window = None;
                }
            }
        }
    }

    fn count_non_finite(&mut self) {
        self.counters.non_finite = self.counters.non_finite.saturating_add(1);
    }

    /// Replaces any non-finite field by zeros with accuracy 0 (counted).
    fn guard(&mut self, mut d: ImuData) -> ImuData {
        let mut bad = false;
        for s in [
            &mut d.gyro,
            &mut d.accel,
            &mut d.compass,
            &mut d.linear_accel,
            &mut d.accel_velocity,
        ] {
            if !(s.x.is_finite() && s.y.is_finite() && s.z.is_finite()) {
                *s = SensorData::default();
                bad = true;
            }
        }
        let q = d.dmp_quat;
        if !(q.w.is_finite() && q.x.is_finite() && q.y.is_finite() && q.z.is_finite()) {
            d.dmp_quat = self.last.dmp_quat;
            bad = true;
        }
        for v in [&mut d.heading, &mut d.temperature] {
            if !v.is_finite() {
                *v = 0.0;
                bad = true;
            }
        }
        if bad {
            self.count_non_finite();
        }
        d
    }
}

/// rad/s per gyro count: 10 / `gyro_lsb_per_10dps` °/s, in radians.
const RAD_S_PER_LSB: f32 =
    10.0 / IMU_SCALE.gyro_lsb_per_10dps as f32 * (core::f32::consts::PI / 180.0);
/// m/s² per accelerometer count: g / `accel_lsb_per_g`.
const MS2_PER_LSB: f32 = G / IMU_SCALE.accel_lsb_per_g as f32;

/// The only operators on nalgebra's types. Clippy's `arithmetic_side_effects` flags every
/// operator of a non-primitive type; these are fixed-size f32 matrices, vectors and quaternions,
/// whose operators cannot panic or wrap (an infinity or NaN is caught by the caller's checks).
#[allow(clippy::arithmetic_side_effects)]
mod ops {
    use super::G;
    use nalgebra::{Matrix3, UnitQuaternion, Vector3};

    /// A row-major i8 matrix as a float matrix.
    pub fn matrix(m: [i8; 9]) -> Matrix3<f32> {
        let [a, b, c, d, e, f, g, h, i] = m.map(f32::from);
        Matrix3::new(a, b, c, d, e, f, g, h, i)
    }

    /// `k · M · v`: sensor counts to board-frame units.
    pub fn rotate(m: [i8; 9], v: &Vector3<f32>, k: f32) -> Vector3<f32> {
        matrix(m) * v * k
    }

    /// `M_old · M_newᵀ`: the turn from the new board axes to the old ones.
    pub fn change_of_axes(old: [i8; 9], new: [i8; 9]) -> Matrix3<f32> {
        matrix(old) * matrix(new).transpose()
    }

    /// `q · r`.
    pub fn compose(q: &UnitQuaternion<f32>, r: &UnitQuaternion<f32>) -> UnitQuaternion<f32> {
        q * r
    }

    /// A world-frame specific force with gravity's (0, 0, g) taken off.
    pub fn minus_gravity(v: &Vector3<f32>) -> Vector3<f32> {
        v - Vector3::z() * G
    }
}

fn finite_quat(q: &UnitQuaternion<f32>) -> bool {
    q.coords.iter().all(|v| v.is_finite())
}

fn sensor(v: Vector3<f32>, accuracy: i8) -> SensorData {
    SensorData {
        x: v.x,
        y: v.y,
        z: v.z,
        accuracy,
    }
}

/// The quaternion as (w, x, y, z) with w ≥ 0 (q and −q are the same rotation).
fn quat_data(q: &UnitQuaternion<f32>) -> QuaternionData {
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    QuaternionData {
        w: s * q.w,
        x: s * q.i,
        y: s * q.j,
        z: s * q.k,
    }
}

/// Heading of the board's x axis, degrees in [0, 360), clockwise seen from above (z up), from the
/// world x axis: the negated yaw.
fn heading_deg(q: &UnitQuaternion<f32>) -> f32 {
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    // World-frame components of the board's x axis: first column of R(q).
    let left_of_x = 2.0 * (x * y + w * z);
    let along_x = 1.0 - 2.0 * (y * y + z * z);
    let yaw = RealField::atan2(left_of_x, along_x).to_degrees();
    // atan2 is within ±180°. 0 − yaw, not −yaw: a yaw of +0 gives +0, not −0.
    let h = if yaw > 0.0 { 360.0 - yaw } else { 0.0 - yaw };
    // 360 − a tiny yaw rounds to 360.0 itself.
    if h >= 360.0 || !h.is_finite() {
        0.0
    } else {
        h
    }
}

#[cfg(test)]
mod tests;

#[cfg(any(test, kani))]
mod verification;
