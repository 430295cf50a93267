//! OXTS GPS/IMU records of KITTI raw drives and the ground-truth poses derived from them,
//! exactly as the KITTI odometry ground truth and pykitti (`utils.pose_from_oxts_packet`,
//! `load_oxts_packets_and_poses`) derive them:
//!
//! * Mercator projection with the scale of the first record, `s = cos(lat₀·π/180)`:
//!   `tx = s·er·lon·π/180`, `ty = s·er·ln(tan((90+lat)·π/360))`, `tz = alt`, `er = 6378137 m`;
//! * `R = Rz(yaw)·Ry(pitch)·Rx(roll)`;
//! * `T_w_imu = [R | t − t₀]` (origin at the first record).
//!
//! Each record file holds one line of 30 whitespace-separated fields (`oxts/dataformat.txt`);
//! the first six (lat, lon, alt, roll, pitch, yaw) are the ones used here.

use std::path::Path;

use nalgebra::{Matrix3, Matrix4, Vector3};

use super::calib::homogeneous;
use super::text::{numbered_lines, parse_f64, read_text};
use super::DatasetError;

/// Number of fields in an OXTS record (`dataformat.txt`).
pub const OXTS_FIELDS: usize = 30;

/// Earth radius used by KITTI's Mercator projection, metres.
const EARTH_RADIUS_M: f64 = 6_378_137.0;

/// The pose-relevant part of one OXTS record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OxtsPacket {
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Altitude, metres.
    pub alt_m: f64,
    /// Roll, radians (positive = left side up).
    pub roll_rad: f64,
    /// Pitch, radians (positive = front down).
    pub pitch_rad: f64,
    /// Heading, radians (0 = east, counter-clockwise positive).
    pub yaw_rad: f64,
}

/// Reads one OXTS record file (the first non-blank line; 30 fields, all numeric).
pub fn read_packet(path: &Path) -> Result<OxtsPacket, DatasetError> {
    let text = read_text(path)?;
    parse_packet(path, &text)
}

/// Parses the text of one OXTS record file (`path` only names the file in errors).
pub fn parse_packet(path: &Path, text: &str) -> Result<OxtsPacket, DatasetError> {
    let Some((line, l)) = numbered_lines(text).next() else {
        return Err(DatasetError::OxtsFields { path: path.to_path_buf(), got: 0 });
    };
    let tokens: Vec<&str> = l.split_whitespace().collect();
    if tokens.len() != OXTS_FIELDS {
        return Err(DatasetError::OxtsFields { path: path.to_path_buf(), got: tokens.len() });
    }
    let mut v = [0.0; OXTS_FIELDS];
    for (slot, t) in v.iter_mut().zip(&tokens) {
        *slot = parse_f64(path, line, t)?;
    }
    if !(-90.0..=90.0).contains(&v[0]) {
        return Err(DatasetError::Parse {
            path: path.to_path_buf(),
            line,
            msg: format!("latitude {} outside [-90, 90]", v[0]),
        });
    }
    Ok(OxtsPacket {
        lat_deg: v[0],
        lon_deg: v[1],
        alt_m: v[2],
        roll_rad: v[3],
        pitch_rad: v[4],
        yaw_rad: v[5],
    })
}

fn rotx(t: f64) -> Matrix3<f64> {
    let (s, c) = t.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

fn roty(t: f64) -> Matrix3<f64> {
    let (s, c) = t.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

fn rotz(t: f64) -> Matrix3<f64> {
    let (s, c) = t.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// Rotation and Mercator translation of one record (pykitti's `pose_from_oxts_packet`).
pub fn pose_from_packet(p: &OxtsPacket, scale: f64) -> (Matrix3<f64>, Vector3<f64>) {
    let pi = core::f64::consts::PI;
    // Same operation order as pykitti so the rounding matches too.
    let tx = scale * p.lon_deg * pi * EARTH_RADIUS_M / 180.0;
    let ty = scale * EARTH_RADIUS_M * ((90.0 + p.lat_deg) * pi / 360.0).tan().ln();
    let tz = p.alt_m;
    let r = rotz(p.yaw_rad) * (roty(p.pitch_rad) * rotx(p.roll_rad));
    (r, Vector3::new(tx, ty, tz))
}

/// `T_w_imu` for every record: world = east-north-up with its origin at the first record.
pub fn imu_poses(packets: &[OxtsPacket]) -> Vec<Matrix4<f64>> {
    let Some(first) = packets.first() else { return Vec::new() };
    let scale = (first.lat_deg * core::f64::consts::PI / 180.0).cos();
    let origin = pose_from_packet(first, scale).1;
    packets
        .iter()
        .map(|p| {
            let (r, t) = pose_from_packet(p, scale);
            homogeneous(&r, &(t - origin))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Drive 2011_09_26_0005, frame 0, verbatim.
    const REC: &str = "49.011212804408 8.4228850417969 112.83492279053 0.022447 1e-05 -1.2219096732051 -3.3256321640686 1.1384311814592 3.5147680214713 0.037625160413037 -0.03878884255623 -0.29437452763793 0.037166856911681 9.9957015129717 -0.30581030960531 -0.19635662515203 9.9942128010936 -0.017332142869546 0.024792163815438 0.14511808479348 -0.017498934149631 0.021393359392165 0.14563031426063 0.49229361157748 0.068883960397178 4 10 4 4 0\n";

    #[test]
    fn parses_a_real_record() {
        let p = parse_packet(Path::new("0000000000.txt"), REC).unwrap();
        assert_eq!(p.lat_deg, 49.011212804408);
        assert_eq!(p.yaw_rad, -1.2219096732051);
    }

    #[test]
    fn short_record_names_file_and_count() {
        let short: String = REC.split_whitespace().take(29).collect::<Vec<_>>().join(" ");
        let e = parse_packet(Path::new("0000000007.txt"), &short).unwrap_err();
        assert_eq!(e, DatasetError::OxtsFields { path: "0000000007.txt".into(), got: 29 });
        assert!(e.to_string().contains("0000000007.txt"));
        let e = parse_packet(Path::new("x.txt"), "\n\n").unwrap_err();
        assert!(matches!(e, DatasetError::OxtsFields { got: 0, .. }));
    }

    #[test]
    fn rotation_is_z_y_x_and_orthonormal() {
        let p = OxtsPacket {
            lat_deg: 49.0,
            lon_deg: 8.4,
            alt_m: 100.0,
            roll_rad: 0.1,
            pitch_rad: -0.2,
            yaw_rad: 1.3,
        };
        let (r, t) = pose_from_packet(&p, (49.0f64).to_radians().cos());
        let expect = rotz(1.3) * roty(-0.2) * rotx(0.1);
        assert!((r - expect).norm() < 1e-15);
        assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-14);
        assert!((r.determinant() - 1.0).abs() < 1e-14);
        assert_eq!(t.z, 100.0);
        // Rx: positive roll lifts +y towards +z.
        assert!((rotx(0.5) * Vector3::y()).z > 0.0);
    }

    #[test]
    fn first_pose_is_at_the_origin_and_one_metre_north_is_one_metre() {
        let a = OxtsPacket {
            lat_deg: 0.0,
            lon_deg: 0.0,
            alt_m: 5.0,
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: 0.0,
        };
        // At the equator (scale 1) a metre of northing is 1/er rad of latitude.
        let b = OxtsPacket { lat_deg: (1.0 / EARTH_RADIUS_M).to_degrees(), ..a };
        let poses = imu_poses(&[a, b]);
        assert_eq!(poses[0], Matrix4::identity());
        assert!((poses[1][(1, 3)] - 1.0).abs() < 1e-6, "{}", poses[1]);
        assert!(imu_poses(&[]).is_empty());
    }
}
