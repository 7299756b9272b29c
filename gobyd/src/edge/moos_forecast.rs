//! The link forecast on MOOS: CTD samples and the navigation read from the
//! community, and each forecast written as variables an IvP Helm behaviour
//! takes through its `updates` parameter (`ACOMMS_DEPTH_UPDATES =
//! "depth=35"` for `BHV_ConstantDepth`), one summary per peer and the
//! whole forecast as JSON.

use gobyd_protocol::forecast::{CtdSample, Forecast};
use moos::{Mail, Value};
use protos::goby::apps::protobuf::LinkForecastConfig;

use crate::edge::json::lines::forecast_line;
use crate::event::{ForecastEvent, ForecastInput};

/// The forecast's MOOS variables.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ForecastVars {
    ctd: String,
    nav_x: String,
    nav_y: String,
    nav_depth: String,
    nav_lat: String,
    nav_lon: String,
    request: String,
    depth_updates: String,
    peers: String,
    forecast: String,
}

impl ForecastVars {
    /// The variables of `config`'s forecast section.
    pub fn of(config: &LinkForecastConfig) -> Self {
        ForecastVars {
            ctd: config.ctd_var().into(),
            nav_x: config.nav_x_var().into(),
            nav_y: config.nav_y_var().into(),
            nav_depth: config.nav_depth_var().into(),
            nav_lat: config.nav_lat_var().into(),
            nav_lon: config.nav_lon_var().into(),
            request: config.request_var().into(),
            depth_updates: config.depth_updates_var().into(),
            peers: config.peers_var().into(),
            forecast: config.forecast_var().into(),
        }
    }

    /// The variables read.
    pub fn registered(&self) -> Vec<String> {
        [
            &self.ctd,
            &self.nav_x,
            &self.nav_y,
            &self.nav_depth,
            &self.nav_lat,
            &self.nav_lon,
            &self.request,
        ]
        .into_iter()
        .filter(|v| !v.is_empty())
        .cloned()
        .collect()
    }

    /// What `mail` gives the forecast, if it is one of its variables: an
    /// error names the variable and what is wrong.
    pub fn input(&self, mail: &Mail) -> Option<Result<ForecastInput, String>> {
        let key = mail.key.as_str();
        let number = || match &mail.value {
            Value::Double(v) => Ok(*v),
            Value::String(s) => s
                .trim()
                .parse::<f64>()
                .map_err(|_| format!("{key}: {s:?} is not a number")),
            Value::Binary(_) => Err(format!("{key}: binary, not a number")),
        };
        let nav = |x, y, depth| ForecastInput::Nav {
            x,
            y,
            depth,
            lat: None,
            lon: None,
        };
        let geo = |lat, lon| ForecastInput::Nav {
            x: None,
            y: None,
            depth: None,
            lat,
            lon,
        };
        let input = if key == self.ctd {
            ctd_sample(&mail.value, mail.time).map(|s| ForecastInput::Ctd {
                samples: vec![s],
                reply: None,
            })
        } else if key == self.nav_x {
            number().map(|v| nav(Some(v), None, None))
        } else if key == self.nav_y {
            number().map(|v| nav(None, Some(v), None))
        } else if key == self.nav_depth {
            number().map(|v| nav(None, None, Some(v)))
        } else if key == self.nav_lat {
            number().map(|v| geo(Some(v), None))
        } else if key == self.nav_lon {
            number().map(|v| geo(None, Some(v)))
        } else if key == self.request {
            Ok(ForecastInput::Request { reply: None })
        } else {
            return None;
        };
        Some(input)
    }

    /// The variables a forecast event writes.
    pub fn publications(&self, event: &ForecastEvent) -> Vec<(String, Value)> {
        let json = Value::String(forecast_line(event).line());
        let ForecastEvent::Forecast(f) = event else {
            return vec![(self.forecast.clone(), json)];
        };
        let mut out = Vec::new();
        if let Some(depth) = f.band.as_ref().and_then(|b| b.recommended) {
            out.push((
                self.depth_updates.clone(),
                Value::String(format!("depth={depth}")),
            ));
        }
        out.push((self.peers.clone(), Value::String(peers_summary(f))));
        out.push((self.forecast.clone(), json));
        out
    }
}

/// `node=2,range=3120,snr=9.8,fer=0.12` per peer (`fer` of the band's
/// rate, or of the first rate), `;` between.
pub fn peers_summary(f: &Forecast) -> String {
    let rate = f.band.as_ref().map(|b| b.rate);
    f.peers
        .iter()
        .map(|p| {
            let fer = p
                .rates
                .iter()
                .find(|r| Some(r.rate) == rate)
                .or(p.rates.first())
                .map_or(1.0, |r| r.fer);
            let snr = p.snr.map_or("none".to_string(), |s| format!("{s:.1}"));
            format!(
                "node={},range={:.0},snr={snr},fer={fer:.3}",
                p.node, p.range
            )
        })
        .collect::<Vec<_>>()
        .join(";")
}

/// A CTD sample written as `depth=12.5,temperature=21.3,salinity=38.1`
/// (`time=` optional; the mail's time otherwise) or as the JSON object.
fn ctd_sample(value: &Value, time: f64) -> Result<CtdSample, String> {
    let Value::String(text) = value else {
        return Err("a CTD sample is a string: \"depth=D,temperature=T,salinity=S\"".into());
    };
    let text = text.trim();
    if text.starts_with('{') {
        let mut s: CtdSample =
            serde_json::from_str(text).map_err(|e| format!("CTD sample {text:?}: {e}"))?;
        s.time = s.time.or(Some(time));
        return Ok(s);
    }
    let mut fields = [None; 4];
    for part in text.split(',') {
        let (k, v) = part
            .split_once('=')
            .ok_or_else(|| format!("CTD sample {text:?}: {part:?} is not key=value"))?;
        let i = ["time", "depth", "temperature", "salinity"]
            .iter()
            .position(|n| *n == k.trim())
            .ok_or_else(|| format!("CTD sample {text:?}: unknown key {:?}", k.trim()))?;
        fields[i] = Some(
            v.trim()
                .parse::<f64>()
                .map_err(|_| format!("CTD sample {text:?}: {k}={v:?} is not a number"))?,
        );
    }
    let need = |i: usize, name: &str| {
        fields[i].ok_or_else(|| format!("CTD sample {text:?}: {name} is missing"))
    };
    Ok(CtdSample {
        time: Some(fields[0].unwrap_or(time)),
        depth: need(1, "depth")?,
        temperature: need(2, "temperature")?,
        salinity: need(3, "salinity")?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ctd_sample_reads_as_key_values_or_json_and_nan_passes_to_the_check() {
        let s = ctd_sample(
            &Value::String("depth=3,temperature=20,salinity=38".into()),
            5.0,
        )
        .unwrap();
        assert_eq!((s.time, s.depth, s.temperature), (Some(5.0), 3.0, 20.0));
        let s = ctd_sample(
            &Value::String("depth=3,temperature=nan,salinity=38".into()),
            5.0,
        )
        .unwrap();
        assert!(s.temperature.is_nan());
        let j = r#"{"depth": 4, "temperature": 19, "salinity": 38}"#;
        assert_eq!(
            ctd_sample(&Value::String(j.into()), 1.0).unwrap().depth,
            4.0
        );
        let e = ctd_sample(&Value::String("depth=3,salinity=38".into()), 1.0).unwrap_err();
        assert!(e.contains("temperature is missing"), "{e}");
    }
}
