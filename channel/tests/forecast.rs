//! The GRAM forecast on the GLINT10-like summer profile: the downward
//! refracting thermocline makes the deep water the better place for a
//! vehicle to hear a buoy at 30 m, kilometres away (thesis Fig. 4.7).

use std::sync::atomic::AtomicBool;

use goby_channel::{
    ChannelError, Environment, ForecastConfig, Forecaster, HalfSpace, MicroModemBand, Modem,
    NoiseModel, Position, SspPoint,
};

fn summer() -> Environment {
    let points = [
        (0.0, 1528.0),
        (8.0, 1527.6),
        (12.0, 1524.0),
        (18.0, 1516.0),
        (25.0, 1510.5),
        (32.0, 1508.2),
        (45.0, 1507.4),
        (70.0, 1507.0),
        (111.0, 1507.3),
    ];
    let mut env = Environment::simple(
        points.iter().map(|&(z, c)| SspPoint::new(z, c)).collect(),
        HalfSpace {
            speed: 1600.0,
            shear_speed: 0.0,
            density: 1.7,
            attenuation: 0.8,
            shear_attenuation: 0.0,
        },
    );
    env.volume_attenuation = goby_channel::VolumeAttenuation::Thorp;
    env
}

fn forecaster() -> Forecaster {
    let mut config = ForecastConfig::new(
        Modem::micromodem(MicroModemBand::C),
        NoiseModel::beaufort(2, 0.5),
    );
    config.range_window = 200.0;
    Forecaster::new(summer(), config).unwrap()
}

#[test]
fn the_best_depth_is_below_the_warm_layer_at_three_kilometres() {
    let f = forecaster();
    let buoy = Position {
        x: 0.0,
        y: 0.0,
        depth: 30.0,
    };
    let auv = Position {
        x: 2400.0,
        y: 1800.0,
        depth: 5.0,
    };
    let d = f.best_depth(&auv, &buoy, (2.0, 100.0), 2.0, None).unwrap();
    let best = d.best_depth().unwrap();
    assert!(best > 20.0, "best depth {best} m");
    let shallow = d.tl[0].unwrap();
    let deep = d.tl[d.best.unwrap()].unwrap();
    assert!(shallow > deep + 6.0, "surface {shallow} dB, best {deep} dB");
    // The objective of BHV_AcommsDepth peaks there too.
    let o = d.objective(108.0);
    let top = o.iter().cloned().fold(0.0, f64::max);
    assert_eq!(o[d.best.unwrap()], top);
}

#[test]
fn links_to_peers_give_fer_per_rate_and_delay() {
    let f = forecaster();
    let own = Position {
        x: 0.0,
        y: 0.0,
        depth: 30.0,
    };
    let peers = [
        Position {
            x: 500.0,
            y: 0.0,
            depth: 40.0,
        },
        Position {
            x: 3000.0,
            y: 0.0,
            depth: 60.0,
        },
        Position {
            x: 3000.0,
            y: 0.0,
            depth: 4.0,
        },
    ];
    let links = f.links(&own, &peers, None).unwrap();
    assert_eq!(links.len(), 3);
    let near = &links[0];
    // The first arrival at 500 m is close to the straight path at ~1510 m/s.
    let delay = near.delay.unwrap();
    assert!((delay - 500.5 / 1510.0).abs() < 0.01, "{delay}");
    assert!(near.snr.unwrap() > links[1].snr.unwrap());
    // Deeper is better at 3 km in summer.
    assert!(links[1].tl.unwrap() < links[2].tl.map_or(f64::INFINITY, |t| t));
    for l in &links {
        assert_eq!(l.rates.len(), 4);
        assert!(l.rates.iter().all(|r| (0.0..=1.0).contains(&r.fer)));
    }
    // Rate 5 needs more SNR than rate 1.
    let r1 = near.rate(1).unwrap().fer;
    let r5 = near.rate(5).unwrap().fer;
    assert!(r5 >= r1);
}

#[test]
fn a_forecast_can_be_cancelled_and_bad_positions_are_named() {
    let f = forecaster();
    let own = Position {
        x: 0.0,
        y: 0.0,
        depth: 30.0,
    };
    let cancel = AtomicBool::new(true);
    let e = f
        .link(
            &own,
            &Position {
                x: 1000.0,
                y: 0.0,
                depth: 20.0,
            },
            Some(&cancel),
        )
        .unwrap_err();
    assert_eq!(e, ChannelError::Cancelled);
    let e = f
        .links(
            &own,
            &[Position {
                x: 1.0,
                y: f64::NAN,
                depth: 20.0,
            }],
            None,
        )
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("peers[0].y"), "{e}");
    let e = f
        .best_depth(
            &own,
            &Position {
                x: 1000.0,
                y: 0.0,
                depth: -2.0,
            },
            (0.0, 50.0),
            1.0,
            None,
        )
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("peer.depth"), "{e}");
}

#[test]
fn a_source_outside_the_water_is_named_not_an_empty_forecast() {
    let f = forecaster();
    let at = |x: f64, depth: f64| Position { x, y: 0.0, depth };
    for (depth, want) in [
        (
            150.0,
            "own.depth: 150 m is below the bottom (111 m at the source)",
        ),
        (111.0, "own.depth: 111 m is on the bottom"),
        (0.0, "own.depth: 0 m is on the surface"),
    ] {
        let e = f
            .link(&at(0.0, depth), &at(3000.0, 50.0), None)
            .unwrap_err();
        assert!(e.to_string().starts_with(want), "{e}");
    }
    let e = f
        .best_depth(&at(3000.0, 20.0), &at(0.0, 150.0), (0.0, 50.0), 1.0, None)
        .unwrap_err();
    assert!(
        e.to_string().starts_with("peer.depth: 150 m is below"),
        "{e}"
    );
}

#[test]
fn a_fan_of_ones_own_is_traced_as_given() {
    let mut config = ForecastConfig::new(
        Modem::micromodem(MicroModemBand::C),
        NoiseModel::beaufort(2, 0.5),
    );
    // A file's fan: 301 beams over ±30°, its box out to 2 km only.
    let fan = goby_channel::Beams::new(301, -30.0, 30.0, 111.0, 2000.0);
    config.fan = Some(fan.clone());
    let f = Forecaster::new(summer(), config).unwrap();
    assert_eq!(f.beams(111.0, 3000.0), fan);
    let at = |x: f64, depth: f64| Position { x, y: 0.0, depth };
    let links = f
        .links(&at(0.0, 30.0), &[at(1000.0, 50.0), at(3000.0, 50.0)], None)
        .unwrap();
    assert!(links[0].tl.is_some());
    assert_eq!(links[1].tl, None, "beyond the fan's box");
}
