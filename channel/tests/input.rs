//! Bad input gets an error naming the field, or the file, line and field;
//! good files round-trip through the writer.

use std::path::Path;

use goby_channel::bellhop::{self, RunKind};
use goby_channel::{
    Beams, Boundary, Channel, ChannelError, CtdSample, Environment, EstimatorConfig, Grid,
    HalfSpace, ProfileEstimator, RunMode, SspPoint, Threads,
};

fn sand() -> HalfSpace {
    HalfSpace {
        speed: 1600.0,
        shear_speed: 0.0,
        density: 1.7,
        attenuation: 0.8,
        shear_attenuation: 0.0,
    }
}

fn env(points: Vec<SspPoint>) -> Environment {
    Environment::simple(points, sand())
}

fn field_of(e: ChannelError) -> String {
    match e {
        ChannelError::Invalid { field, .. } => field,
        other => panic!("not a field error: {other}"),
    }
}

#[test]
fn a_profile_with_one_point_is_refused() {
    let e = Channel::new(env(vec![SspPoint::new(0.0, 1500.0)]), 1000.0)
        .err()
        .unwrap();
    assert_eq!(field_of(e.clone()), "profile");
    assert!(e.to_string().contains("at least two points"), "{e}");
}

/// The field a two-point profile is refused for.
fn refused_field(top: (f64, f64), bottom: (f64, f64)) -> String {
    let points = vec![
        SspPoint::new(top.0, top.1),
        SspPoint::new(bottom.0, bottom.1),
    ];
    field_of(Channel::new(env(points), 1000.0).err().unwrap())
}

#[test]
fn negative_and_nan_depths_are_refused() {
    let c = 1500.0;
    assert_eq!(
        refused_field((-5.0, c), (100.0, c)),
        "profile.points[0].depth"
    );
    assert_eq!(
        refused_field((0.0, c), (f64::NAN, c)),
        "profile.points[1].depth"
    );
    assert_eq!(
        refused_field((0.0, f64::NAN), (100.0, c)),
        "profile.points[0].speed"
    );
    assert_eq!(
        refused_field((50.0, c), (20.0, c)),
        "profile.points[1].depth"
    );
}

#[test]
fn a_source_below_the_bottom_is_refused() {
    let ch = Channel::new(
        env(vec![
            SspPoint::new(0.0, 1500.0),
            SspPoint::new(100.0, 1500.0),
        ]),
        1000.0,
    )
    .unwrap();
    let beams = Beams::new(11, -10.0, 10.0, 100.0, 1000.0);
    let grid = Grid {
        depths: vec![10.0],
        ranges: vec![500.0],
    };
    for (depth, want) in [
        (120.0, "below the bottom"),
        (-1.0, "negative"),
        (f64::NAN, "finite"),
    ] {
        let e = ch
            .tl_field(
                depth,
                &grid,
                RunMode::Incoherent,
                &beams,
                Threads::One,
                None,
            )
            .err()
            .unwrap();
        assert!(
            e.to_string().starts_with("source.depth") && e.to_string().contains(want),
            "{e}"
        );
    }
    let bad_grid = Grid {
        depths: vec![-3.0],
        ranges: vec![500.0],
    };
    let e = ch
        .tl_field(
            50.0,
            &bad_grid,
            RunMode::Incoherent,
            &beams,
            Threads::One,
            None,
        )
        .err()
        .unwrap();
    assert_eq!(field_of(e), "grid.depths[0]");
}

#[test]
fn nan_ctd_samples_are_refused_and_change_nothing() {
    let mut est = ProfileEstimator::new(EstimatorConfig::default()).unwrap();
    let good = CtdSample {
        time: 0.0,
        depth: 5.0,
        temperature: 20.0,
        salinity: 38.0,
    };
    est.add(&good).unwrap();
    let e = est
        .add(&CtdSample {
            salinity: f64::NAN,
            ..good
        })
        .unwrap_err();
    assert_eq!(field_of(e), "sample.salinity");
    assert_eq!(est.len(), 1);
}

fn read(
    name: &str,
    text: &str,
    companions: &[(&str, &str)],
) -> Result<bellhop::EnvFile, goby_channel::ParseError> {
    bellhop::read_env(name, text, &mut |ext| {
        companions
            .iter()
            .find(|(e, _)| *e == ext)
            .map(|(_, t)| t.to_string())
            .ok_or_else(|| "no such file".to_string())
    })
}

const WEDGE: &str = include_str!("data/bellhop/wedge.env");

#[test]
fn a_bathymetry_file_that_does_not_parse_names_its_line() {
    let e = read(
        "wedge.env",
        WEDGE,
        &[("bty", "'L'\n3\n0.0 200.0\n2.0 1x0.0\n4.0 20.0\n")],
    )
    .unwrap_err();
    assert_eq!((e.file.as_str(), e.line), ("wedge.bty", 4), "{e}");
    assert!(e.field.contains("point 2"), "{e}");
    let e = read(
        "wedge.env",
        WEDGE,
        &[("bty", "'L'\n3\n0.0 200.0\n4.0 20.0\n")],
    )
    .unwrap_err();
    assert!(e.to_string().contains("the file ends"), "{e}");
    let e = read(
        "wedge.env",
        WEDGE,
        &[("bty", "'L'\n2\n0.0 250.0\n4.0 20.0\n")],
    )
    .unwrap_err();
    assert!(e.to_string().contains("drops below"), "{e}");
    let e = read("wedge.env", WEDGE, &[]).unwrap_err();
    assert_eq!(e.file, "wedge.bty");
    assert!(e.message.contains("cannot be read"), "{e}");
}

#[test]
fn env_errors_name_line_and_field() {
    let bad = WEDGE.replace("'CVW'", "'XVW'");
    let e = read("w.env", &bad, &[]).unwrap_err();
    assert_eq!((e.line, e.field.as_str()), (4, "top option"), "{e}");
    let bad = WEDGE.replace("  200.0  1500.0 /", "  200.0  abc /");
    let e = read("w.env", &bad, &[]).unwrap_err();
    assert_eq!(e.line, 7, "{e}");
    assert!(e.field.starts_with("SSP point 2"), "{e}");
    let cut: String = WEDGE.lines().take(14).collect::<Vec<_>>().join("\n");
    let e = read("w.env", &cut, &[("bty", "'L'\n2\n0 200\n4 20\n")]).unwrap_err();
    assert!(e.to_string().contains("the file ends"), "{e}");
    let bad = WEDGE.replace("'C'\t", "'CC'\t");
    let e = read("w.env", &bad, &[("bty", "'L'\n2\n0 200\n4 20\n")]).unwrap_err();
    assert!(e.message.contains("not supported"), "{e}");
}

#[test]
fn every_case_round_trips_through_the_writer() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bellhop");
    for case in ["pekeris", "munk", "summer", "wedge", "options/grain"] {
        let text = std::fs::read_to_string(dir.join(format!("{case}.env"))).unwrap();
        let comp = |ext: &str| {
            std::fs::read_to_string(dir.join(format!("{case}.{ext}"))).map_err(|e| e.to_string())
        };
        let a = bellhop::read_env(&format!("{case}.env"), &text, &mut |e| comp(e)).unwrap();
        assert_eq!(a.run, RunKind::Coherent);
        let (written, companions) = bellhop::write_env(&a);
        let b = bellhop::read_env("again.env", &written, &mut |ext| {
            companions
                .iter()
                .find(|(e, _)| *e == ext)
                .map(|(_, t)| t.clone())
                .ok_or_else(|| "missing".into())
        })
        .unwrap();
        assert_eq!(a.environment, b.environment, "{case}");
        assert_eq!(a.beams, b.beams, "{case}");
        assert_eq!(a.source_depths, b.source_depths, "{case}");
        assert_eq!(a.grid.depths, b.grid.depths, "{case}");
        for (x, y) in a.grid.ranges.iter().zip(&b.grid.ranges) {
            assert!((x - y).abs() < 1e-3, "{case}: {x} {y}");
        }
    }
}

#[test]
fn a_rough_surface_loses_more_than_a_flat_one() {
    let points = vec![SspPoint::new(0.0, 1500.0), SspPoint::new(50.0, 1500.0)];
    let mut rough = env(points.clone());
    rough.surface_roughness = 0.3;
    let grid = Grid {
        depths: vec![25.0],
        ranges: vec![2000.0],
    };
    let beams = Beams::new(301, -60.0, 60.0, 50.0, 2000.0);
    let tl = |e: Environment| {
        let ch = Channel::new(e, 10_000.0).unwrap();
        ch.tl_field(25.0, &grid, RunMode::Incoherent, &beams, Threads::One, None)
            .unwrap()
            .tl(0, 0)
            .unwrap()
    };
    let (flat, rough) = (tl(env(points)), tl(rough));
    assert!(rough > flat + 1.0, "flat {flat} dB, rough {rough} dB");
    assert!(matches!(
        Environment::simple(vec![], sand()).surface,
        Boundary::Vacuum
    ));
}

/// Every prefix of every case's .env, and each with one byte replaced,
/// reads to a value or an error, never a panic; so do cut and corrupted
/// .shd and .arr files.
#[test]
fn truncated_and_garbled_files_never_panic() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bellhop");
    let bty = "'L'\n2\n0.0 200.0\n4.0 20.0\n";
    let companions = |ext: &str| -> Result<String, String> {
        if ext == "bty" {
            Ok(bty.to_string())
        } else {
            Err("none".into())
        }
    };
    for case in ["pekeris", "munk", "summer", "wedge", "options/grain"] {
        let text = std::fs::read_to_string(dir.join(format!("{case}.env"))).unwrap();
        let bytes = text.as_bytes();
        for cut in (0..bytes.len()).step_by(3) {
            let t = String::from_utf8_lossy(&bytes[..cut]);
            let _ = bellhop::read_env("cut.env", &t, &mut |e| companions(e));
        }
        for (i, junk) in (0..bytes.len())
            .step_by(5)
            .zip([b'/', b'x', b'\'', b'-', b'9', b' ', b'\n'].iter().cycle())
        {
            let mut b = bytes.to_vec();
            b[i] = *junk;
            let t = String::from_utf8_lossy(&b);
            if let Ok(file) = bellhop::read_env("junk.env", &t, &mut |e| companions(e)) {
                // What reads must run or be refused with an error.
                if let (Some(mode), Ok(ch)) = (
                    file.run.mode(),
                    Channel::new(file.environment.clone(), file.frequency),
                ) {
                    let mut beams = file.beams.clone();
                    beams.angles = Beams::fan(5, -10.0, 10.0);
                    let _ = ch.tl_field(
                        file.source_depths[0],
                        &file.grid,
                        mode,
                        &beams,
                        Threads::One,
                        None,
                    );
                }
            }
        }
    }
    let field = {
        let ch = Channel::new(
            env(vec![
                SspPoint::new(0.0, 1500.0),
                SspPoint::new(100.0, 1500.0),
            ]),
            1000.0,
        )
        .unwrap();
        let grid = Grid {
            depths: vec![10.0, 20.0],
            ranges: vec![100.0, 200.0, 300.0],
        };
        let beams = Beams::new(21, -20.0, 20.0, 100.0, 300.0);
        ch.tl_field(50.0, &grid, RunMode::Coherent, &beams, Threads::One, None)
            .unwrap()
    };
    let shd = bellhop::write_shd("t", 1000.0, std::slice::from_ref(&field));
    assert_eq!(
        bellhop::read_shd("t.shd", &shd)
            .unwrap()
            .field(0)
            .unwrap()
            .depths,
        field.depths
    );
    for cut in (0..shd.len()).step_by(13) {
        // The last record's padding may go; anything shorter is an error.
        let last_data = shd.len() - 41 * 4 + 2 * 3 * 4;
        let read = bellhop::read_shd("t.shd", &shd[..cut]);
        assert_eq!(read.is_err(), cut < last_data, "cut at {cut}");
    }
    for i in (0..200).step_by(3) {
        let mut b = shd.clone();
        b[i] ^= 0x5a;
        let _ = bellhop::read_shd("t.shd", &b);
    }
}

#[test]
fn arrivals_round_trip_through_the_arr_file_and_cut_files_are_errors() {
    let ch = Channel::new(
        env(vec![
            SspPoint::new(0.0, 1500.0),
            SspPoint::new(100.0, 1500.0),
        ]),
        1000.0,
    )
    .unwrap();
    let grid = Grid {
        depths: vec![10.0, 60.0],
        ranges: vec![500.0, 1500.0],
    };
    let beams = Beams::new(101, -30.0, 30.0, 100.0, 1500.0);
    let field = ch
        .arrivals(50.0, &grid, &beams, Threads::One, None)
        .unwrap();
    assert!(
        field.at(0, 0).len() >= 2,
        "direct and surface-reflected paths"
    );
    let text = bellhop::write_arr(1000.0, std::slice::from_ref(&field));
    let back = bellhop::read_arr("t.arr", &text).unwrap();
    let a = &back.fields[0];
    assert_eq!(
        (a.depths.clone(), a.ranges.clone()),
        (grid.depths.clone(), grid.ranges.clone())
    );
    for (x, y) in a
        .arrivals
        .iter()
        .flatten()
        .zip(field.arrivals.iter().flatten())
    {
        assert!(
            (x.delay - y.delay).abs() < 1e-9
                && (x.amplitude - y.amplitude).abs() < 1e-9 * y.amplitude.max(1.0)
        );
    }
    // The direct path at 500 m from 50 m to 10 m: 501.6 m at 1500 m/s.
    let direct = field.first_delay(0, 0).unwrap();
    assert!(
        (direct - (500f64.powi(2) + 40f64.powi(2)).sqrt() / 1500.0).abs() < 1e-4,
        "{direct}"
    );
    let lines: Vec<&str> = text.lines().collect();
    for n in 0..lines.len() - 1 {
        let cut = lines[..n].join("\n");
        assert!(
            bellhop::read_arr("t.arr", &cut).is_err(),
            "cut after {n} lines"
        );
    }
}

const PEKERIS: &str = include_str!("data/bellhop/pekeris.env");

/// The error reading `PEKERIS` with `from` replaced by `to`.
fn pekeris_error(from: &str, to: &str) -> goby_channel::ParseError {
    assert!(PEKERIS.contains(from), "no '{from}'");
    read("p.env", &PEKERIS.replace(from, to), &[]).unwrap_err()
}

/// [`pekeris_error`], checked: at `line`, its message holding `want`.
fn refused_at(from: &str, to: &str, line: usize, want: &str) -> goby_channel::ParseError {
    let e = pekeris_error(from, to);
    assert_eq!(e.line, line, "{e}");
    assert!(e.message.contains(want), "{e}");
    e
}

#[test]
fn a_source_on_or_beyond_the_surface_or_the_bottom_names_its_line() {
    for (depth, want) in [
        ("150.0", "150 m is below the bottom (100 m at the source)"),
        ("100.0", "100 m is on the bottom"),
        ("-5.0", "-5 m is above the surface (0 m at the source)"),
        ("0.0", "0 m is on the surface"),
    ] {
        let e = pekeris_error("50.0 /\n", &format!("{depth} /\n"));
        assert_eq!((e.line, e.field.as_str()), (11, "source depths"), "{e}");
        assert!(e.message.contains(want), "{e}");
    }
    // The library says the same of a source on the bottom.
    let file = read("p.env", PEKERIS, &[]).unwrap();
    let ch = Channel::new(file.environment, file.frequency).unwrap();
    let e = ch
        .tl_field(
            100.0,
            &file.grid,
            RunMode::Coherent,
            &file.beams,
            Threads::One,
            None,
        )
        .unwrap_err();
    assert!(
        e.to_string()
            .starts_with("source.depth: 100 m is on the bottom"),
        "{e}"
    );
}

#[test]
fn receivers_beyond_the_water_are_moved_as_bellhop_moves_them_and_said() {
    let file = read(
        "p.env",
        &PEKERIS.replace("0.0 100.0 /", "-20.0 120.0 /"),
        &[],
    )
    .unwrap();
    let d = &file.grid.depths;
    assert_eq!((d[0], d[7], d[50]), (0.0, 0.0, 100.0), "{d:?}");
    assert!(d[8] > 0.0, "{d:?}");
    let w: Vec<String> = file.warnings.iter().map(|w| w.to_string()).collect();
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(
        w[0].starts_with("p.env:13: receiver depths: 8 of 51 above the surface"),
        "{w:?}"
    );
    assert!(
        w[1].contains("below the bottom (100 m) are taken at the bottom"),
        "{w:?}"
    );
    // The grid with its repeated depths is computed.
    let ch = Channel::new(file.environment.clone(), file.frequency).unwrap();
    ch.tl_field(
        50.0,
        &file.grid,
        RunMode::Coherent,
        &file.beams,
        Threads::One,
        None,
    )
    .unwrap();
    assert!(read("p.env", PEKERIS, &[]).unwrap().warnings.is_empty());
}

#[test]
fn a_profile_short_of_the_bottom_or_a_line_without_its_slash_is_named() {
    // One point, or a last point above the bottom depth: the bottom
    // option comes where a depth is expected.
    for (from, to, line, point) in [
        ("  100.0  1500.0 /\n", "", 7, 2),
        ("  100.0  1500.0 /\n", "   60.0  1500.0 /\n", 8, 3),
    ] {
        let want = "without reaching the bottom depth 100 m given on line 5";
        let e = refused_at(from, to, line, want);
        assert!(e.field.starts_with(&format!("SSP point {point}")), "{e}");
    }
    refused_at("    0.0  1500.0 /", "    0.0  1500.0", 6, "without '/'");
}

#[test]
fn box_step_and_unsupported_options_name_their_line() {
    let e = pekeris_error("0.0  101.0  5.1", "0.0  101.0  0.0");
    assert_eq!(
        (e.line, e.field.as_str()),
        (19, "step, box depth, box range"),
        "{e}"
    );
    assert!(
        e.message.contains("box range 0 km is not above zero"),
        "{e}"
    );
    let e = pekeris_error("0.0  101.0  5.1", "-2.0  101.0  5.1");
    assert!(e.message.contains("step -2 m is negative"), "{e}");
    for (option, want) in [
        ("'CVWB'", "biological attenuation"),
        ("'CVW  B'", "broadband run"),
        ("'CVm'", "power law"),
    ] {
        let e = pekeris_error("'CVW'", option);
        assert_eq!((e.line, e.field.as_str()), (4, "top option"), "{e}");
        assert!(
            e.message.contains(want) && e.message.contains("not supported"),
            "{e}"
        );
    }
}

#[test]
fn a_grid_too_large_for_memory_is_an_error_not_an_abort() {
    let e = pekeris_error("51\t", "100000\t");
    assert!(e.message.contains("10100000 receivers"), "{e}");
    let e2 = read(
        "p.env",
        &PEKERIS
            .replace("51\t", "100000\t")
            .replace("101\t", "100000\t"),
        &[],
    )
    .unwrap_err();
    assert_eq!(
        (e2.line, e2.field.as_str()),
        (15, "receiver ranges (km)"),
        "{e2}"
    );
    assert!(e2.message.contains("10000000000 receivers"), "{e2}");
    let grid = Grid {
        depths: (0..100_000).map(f64::from).collect(),
        ranges: (0..100_000).map(f64::from).collect(),
    };
    let e = grid.validate().unwrap_err();
    assert_eq!(field_of(e), "grid");
}

#[test]
fn binary_arrivals_round_trip_and_cut_or_garbled_files_are_errors() {
    let file = read("p.env", PEKERIS, &[]).unwrap();
    let ch = Channel::new(file.environment, file.frequency).unwrap();
    let grid = Grid {
        depths: vec![10.0, 60.0],
        ranges: vec![500.0, 1500.0],
    };
    let field = ch
        .arrivals(50.0, &grid, &file.beams, Threads::One, None)
        .unwrap();
    let bytes = bellhop::write_arr_binary(250.0, std::slice::from_ref(&field));
    let back = bellhop::read_arr_binary("t.arr", &bytes).unwrap();
    assert_eq!(back.frequency, 250.0);
    assert_eq!(back.fields[0].depths, grid.depths);
    for (x, y) in back.fields[0]
        .arrivals
        .iter()
        .flatten()
        .zip(field.arrivals.iter().flatten())
    {
        assert_eq!(
            (x.delay, x.amplitude, x.top_bounces),
            (y.delay, y.amplitude, y.top_bounces)
        );
    }
    for n in 0..bytes.len() {
        assert!(
            bellhop::read_arr_binary("t.arr", &bytes[..n]).is_err(),
            "cut at {n}"
        );
    }
    let mut garbled = bytes.clone();
    garbled[bytes.len() - 3] ^= 0x40;
    assert!(bellhop::read_arr_binary("t.arr", &garbled).is_err());
    let mut huge = bytes;
    huge[0..4].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(bellhop::read_arr_binary("t.arr", &huge).is_err());
}

#[test]
fn bad_profile_half_space_and_angle_values_name_their_line() {
    for (from, to, line, want) in [
        (
            "  100.0  1500.0 /",
            "  100.0  -1500.0 /",
            7,
            "sound speed (m/s) -1500 is not above zero",
        ),
        (
            "  100.0  1600.0 0.0 1.5 0.5 /",
            "  100.0  1600.0 0.0 0.0 0.5 /",
            9,
            "density (g/cm³) 0 is not above zero",
        ),
        (
            "  100.0  1600.0 0.0 1.5 0.5 /",
            "  100.0  1600.0 0.0 1.5 -0.5 /",
            9,
            "attenuation -0.5 is negative",
        ),
        ("-60.0 60.0 /", "-60.0 190.0 /", 18, "° is not within ±180°"),
    ] {
        refused_at(from, to, line, want);
    }
    let twice = PEKERIS
        .replace("601\t", "3\t")
        .replace("-60.0 60.0 /", "-10.0 0.0 0.0 /");
    let e = read("p.env", &twice, &[]).unwrap_err();
    assert_eq!(e.line, 18, "{e}");
    assert!(e.message.contains("0° is given twice"), "{e}");
}

#[test]
fn a_profile_past_the_bottom_or_above_the_surface_names_its_line() {
    let e = refused_at(
        "  100.0  1500.0 /\n",
        "  100.0  1500.0 /\n  150.0  1500.0 /\n",
        8,
        "the profile ended at the bottom depth 100 m (line 5)",
    );
    assert_eq!(e.field, "bottom option");
    refused_at(
        "    0.0  1500.0 /",
        "  -10.0  1500.0 /",
        6,
        "depth -10 m is negative",
    );
}
