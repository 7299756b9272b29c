//! The mission's local grid: metres east (x) and north (y) of the origin
//! (`LatOrigin`, `LongOrigin`), on the UTM projection (WGS84 ellipsoid) of
//! the zone holding the origin, as Goby's `UTMGeodesy` and MOOS's
//! `CMOOSGeodesy::LatLong2LocalUTM` compute it. The projection is the
//! `proj4rs` crate's.

use proj4rs::proj::Proj;
use proj4rs::transform::transform;

/// A local grid around an origin.
#[derive(Debug)]
pub struct LocalGrid {
    latlong: Proj,
    utm: Proj,
    zone: u32,
    origin_east: f64,
    origin_north: f64,
}

impl LocalGrid {
    /// The grid around `lat_origin`, `lon_origin` (degrees); an error for
    /// an origin that is not a position on the Earth.
    pub fn new(lat_origin: f64, lon_origin: f64) -> Result<Self, String> {
        if !(-90.0..=90.0).contains(&lat_origin) || !(-180.0..=180.0).contains(&lon_origin) {
            return Err(format!(
                "the origin {lat_origin}, {lon_origin} is not a latitude and longitude in degrees"
            ));
        }
        // UTM zone of the origin's longitude (1..=60).
        let zone = ((((lon_origin + 180.0) / 6.0).floor() as i64).rem_euclid(60) + 1) as u32;
        let latlong = Proj::from_proj_string("+proj=latlong +ellps=WGS84")
            .map_err(|e| format!("latlong projection: {e}"))?;
        let utm = Proj::from_proj_string(&format!("+proj=utm +ellps=WGS84 +zone={zone}"))
            .map_err(|e| format!("UTM zone {zone}: {e}"))?;
        let mut grid = LocalGrid {
            latlong,
            utm,
            zone,
            origin_east: 0.0,
            origin_north: 0.0,
        };
        let (east, north) = grid.to_utm(lat_origin, lon_origin)?;
        grid.origin_east = east;
        grid.origin_north = north;
        Ok(grid)
    }

    /// The UTM zone of the grid.
    pub fn zone(&self) -> u32 {
        self.zone
    }

    fn to_utm(&self, lat: f64, lon: f64) -> Result<(f64, f64), String> {
        let mut p = (lon.to_radians(), lat.to_radians(), 0.0);
        transform(&self.latlong, &self.utm, &mut p)
            .map_err(|e| format!("cannot project {lat}, {lon}: {e}"))?;
        Ok((p.0, p.1))
    }

    /// Local x (east) and y (north) in metres of a latitude and longitude
    /// in degrees.
    pub fn to_local(&self, lat: f64, lon: f64) -> Result<(f64, f64), String> {
        let (east, north) = self.to_utm(lat, lon)?;
        Ok((east - self.origin_east, north - self.origin_north))
    }

    /// Latitude and longitude in degrees of local x, y in metres.
    pub fn to_geo(&self, x: f64, y: f64) -> Result<(f64, f64), String> {
        let mut p = (x + self.origin_east, y + self.origin_north, 0.0);
        transform(&self.utm, &self.latlong, &mut p)
            .map_err(|e| format!("cannot unproject {x}, {y}: {e}"))?;
        Ok((p.1.to_degrees(), p.0.to_degrees()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_origin_is_zero_and_a_minute_north_is_about_1852_m() {
        let grid = LocalGrid::new(42.5, 10.8).unwrap();
        assert_eq!(grid.zone(), 32);
        let (x, y) = grid.to_local(42.5, 10.8).unwrap();
        assert!(x.abs() < 1e-6 && y.abs() < 1e-6, "{x} {y}");
        let (x, y) = grid.to_local(42.5 + 1.0 / 60.0, 10.8).unwrap();
        // A minute of latitude at 42.5 N is 1851.9 m on WGS84; the grid's
        // north is UTM north, a little off true north away from the
        // central meridian.
        assert!((y - 1852.0).abs() < 3.0, "{y}");
        assert!(x.abs() < 50.0, "{x}");
        let (lat, lon) = grid.to_geo(550.0, 1023.5).unwrap();
        let (x, y) = grid.to_local(lat, lon).unwrap();
        assert!((x - 550.0).abs() < 1e-6 && (y - 1023.5).abs() < 1e-6);
        assert!(LocalGrid::new(95.0, 0.0).is_err());
    }
}
