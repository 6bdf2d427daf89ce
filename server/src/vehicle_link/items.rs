//! Mission items as they travel in MISSION_ITEM_INT: params and z as
//! float32, x/y as integers (degrees ×1e7 in global frames), and the
//! conversion from the planner's [`MavItem`] (what the mission files are
//! written from) and from rows read back out of the files.

use planner_core::export::mission::MavItem;

/// The three lists the mission protocol keeps on a vehicle
/// (MAV_MISSION_TYPE 0, 1 and 2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum MissionKind {
    Mission,
    Fence,
    Rally,
}

impl MissionKind {
    pub fn name(self) -> &'static str {
        match self {
            MissionKind::Mission => "mission",
            MissionKind::Fence => "fence",
            MissionKind::Rally => "rally",
        }
    }
}

/// One item in its wire form, without sequence number and mission type
/// (given by its place in the list and the list).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WireItem {
    pub command: u16,
    pub frame: u8,
    pub params: [f32; 4],
    pub x: i32,
    pub y: i32,
    pub z: f32,
    pub autocontinue: bool,
}

/// MAV_FRAMEs whose x/y are latitude/longitude (GLOBAL, GLOBAL_RELATIVE_ALT,
/// their _INT twins, GLOBAL_TERRAIN_ALT and its _INT twin): degrees ×1e7 in
/// MISSION_ITEM_INT. Other frames carry x/y unscaled.
pub fn is_global_frame(frame: u8) -> bool {
    matches!(frame, 0 | 3 | 5 | 6 | 10 | 11)
}

/// Why an item cannot be put on the wire.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ItemError {
    #[error("latitude {0} is not within -90..90 degrees")]
    Latitude(f64),
    #[error("longitude {0} is not within -180..180 degrees")]
    Longitude(f64),
    #[error("x/y value {0} does not fit a 32-bit integer")]
    XyRange(f64),
    #[error("{what} {value} does not fit a 32-bit float")]
    FloatRange { what: &'static str, value: f64 },
}

impl WireItem {
    /// The item in wire form. Latitude and longitude are rounded to the
    /// nearest 1e-7 degree (as MAVSDK and QGroundControl do).
    pub fn from_mav_item(item: &MavItem, autocontinue: bool) -> Result<WireItem, ItemError> {
        let (x, y) = if is_global_frame(item.frame) {
            if !(-90.0..=90.0).contains(&item.lat) {
                return Err(ItemError::Latitude(item.lat));
            }
            if !(-180.0..=180.0).contains(&item.lon) {
                return Err(ItemError::Longitude(item.lon));
            }
            // In range, so ×1e7 fits an i32 (±1.8e9 < 2.1e9).
            (
                (item.lat * 1e7).round() as i32,
                (item.lon * 1e7).round() as i32,
            )
        } else {
            (whole_i32(item.lat)?, whole_i32(item.lon)?)
        };
        let f32_of = |what: &'static str, value: f64| {
            let v = value as f32;
            if value.is_finite() && !v.is_finite() {
                Err(ItemError::FloatRange { what, value })
            } else {
                Ok(v)
            }
        };
        let [p1, p2, p3, p4] = item.params;
        Ok(WireItem {
            command: item.command,
            frame: item.frame,
            params: [
                f32_of("param1", p1)?,
                f32_of("param2", p2)?,
                f32_of("param3", p3)?,
                f32_of("param4", p4)?,
            ],
            x,
            y,
            z: f32_of("altitude", item.alt)?,
            autocontinue,
        })
    }
}

fn whole_i32(v: f64) -> Result<i32, ItemError> {
    let r = v.round();
    if r.is_finite() && r >= f64::from(i32::MIN) && r <= f64::from(i32::MAX) {
        Ok(r as i32)
    } else {
        Err(ItemError::XyRange(v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn item(frame: u8, lat: f64, lon: f64) -> MavItem {
        MavItem {
            command: 16,
            frame,
            params: [0.0, 0.0, 0.0, f64::NAN],
            lat,
            lon,
            alt: 42.5,
        }
    }

    #[test]
    fn global_positions_are_rounded_to_1e7_degrees() {
        let w = WireItem::from_mav_item(&item(3, 52.123_456_789, -5.000_000_04), true).unwrap();
        assert_eq!((w.x, w.y), (521_234_568, -50_000_000));
        assert!(w.params[3].is_nan());
        assert_eq!(w.z, 42.5);
        // Frame 2 (mission): x/y unscaled.
        let w = WireItem::from_mav_item(&item(2, 3.0, 0.0), true).unwrap();
        assert_eq!((w.x, w.y), (3, 0));
    }

    #[test]
    fn out_of_range_values_are_refused() {
        assert_eq!(
            WireItem::from_mav_item(&item(0, 91.0, 0.0), true),
            Err(ItemError::Latitude(91.0))
        );
        assert!(matches!(
            WireItem::from_mav_item(&item(0, 0.0, f64::NAN), true),
            Err(ItemError::Longitude(v)) if v.is_nan()
        ));
        assert!(WireItem::from_mav_item(&item(2, 3e10, 0.0), true).is_err());
        let mut big = item(3, 0.0, 0.0);
        big.params[0] = 1e300;
        assert!(matches!(
            WireItem::from_mav_item(&big, true),
            Err(ItemError::FloatRange { what: "param1", .. })
        ));
    }
}
