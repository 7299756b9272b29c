//! RockBLOCK's MO webhook: each mobile-originated message, POSTed by the
//! web service to the application's URL, and the JSON Web Token (JWT) that
//! proves the service sent it.
//!
//! The service posts either a form (`application/x-www-form-urlencoded`,
//! its `HTTP_POST` delivery) or a JSON document (`application/json`, its
//! `HTTP_JSON`), with the fields:
//!
//! | field | what | form | JSON |
//! |---|---|---|---|
//! | `imei` | the RockBLOCK's IMEI | text | string |
//! | `serial` | its serial number | text | number |
//! | `momsn` | MO message sequence number | text | number |
//! | `transmit_time` | UTC, e.g. `21-10-31 10:41:50` | text | string |
//! | `iridium_latitude`, `iridium_longitude` | degrees, from the satellites | text | number |
//! | `iridium_cep` | radius of that position's accuracy, km | text | number |
//! | `device_type` | e.g. `ROCKBLOCK` | text | string |
//! | `data` | the message, hex | text | string |
//! | `JWT` | RS256 token over the same fields | text | string |
//!
//! The token's claims are the issuer `iss: "Rock 7"`, the time it was
//! issued `iat` (Unix seconds), and every field above as a string. A post
//! is taken only when the token's signature verifies with the service's
//! public key ([`JwtVerifier`]), its issuer is `Rock 7`, and the fields that
//! matter here (`imei`, `momsn`, `data`, `transmit_time` when both give
//! it) say in the token what the post says: a valid token copied onto other
//! data is refused.

use std::collections::BTreeMap;
use std::fmt;

use jsonwebtoken::{Algorithm, DecodingKey, EncodingKey, Header, Validation};
use serde_json::{Map, Value};

/// The issuer RockBLOCK's tokens name.
pub const ISSUER: &str = "Rock 7";

/// An MO message as the web service posts it.
#[derive(Debug, Clone, PartialEq)]
pub struct MoPost {
    /// The RockBLOCK's IMEI.
    pub imei: String,
    /// MO message sequence number (the transceiver's counter, 0–65535 for
    /// a 9602/9603).
    pub momsn: Option<u64>,
    /// The RockBLOCK's serial number.
    pub serial: Option<u64>,
    /// When the message was sent, UTC, as the service writes it.
    pub transmit_time: Option<String>,
    /// Degrees north, from the Iridium satellites.
    pub iridium_latitude: Option<f64>,
    /// Degrees east.
    pub iridium_longitude: Option<f64>,
    /// Radius (km) of the position's accuracy.
    pub iridium_cep: Option<f64>,
    /// The device's kind (`ROCKBLOCK`).
    pub device_type: Option<String>,
    /// The message (empty for a mailbox check).
    pub data: Vec<u8>,
    /// The service's token, as posted.
    pub jwt: Option<String>,
}

/// Why a webhook post is not taken.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MoRefusal {
    /// The body cannot be read (not a form or JSON, no `imei`, `data` not
    /// hex, a number that is not one): HTTP 400.
    Malformed(String),
    /// No `JWT` field: HTTP 401.
    NoToken,
    /// The token does not verify (signature, algorithm, issuer, not a
    /// token), or says other than the post: HTTP 403.
    BadToken(String),
}

impl MoRefusal {
    /// The HTTP status the webhook answers with.
    pub fn http_status(&self) -> u16 {
        match self {
            MoRefusal::Malformed(_) => 400,
            MoRefusal::NoToken => 401,
            MoRefusal::BadToken(_) => 403,
        }
    }
}

impl fmt::Display for MoRefusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MoRefusal::Malformed(why) => write!(f, "malformed post: {why}"),
            MoRefusal::NoToken => write!(f, "no JWT field: not signed by the service"),
            MoRefusal::BadToken(why) => write!(f, "JWT refused: {why}"),
        }
    }
}

impl std::error::Error for MoRefusal {}

/// The body's format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MoFormat {
    /// `application/x-www-form-urlencoded` (the service's `HTTP_POST`).
    Form,
    /// `application/json` (the service's `HTTP_JSON`).
    Json,
}

impl MoFormat {
    /// The content type of the format.
    pub fn content_type(self) -> &'static str {
        match self {
            MoFormat::Form => "application/x-www-form-urlencoded",
            MoFormat::Json => "application/json; charset=utf-8",
        }
    }
}

/// The fields as text, from a form or a JSON object.
type Fields = BTreeMap<String, String>;

fn json_text(v: &Value) -> Option<String> {
    match v {
        Value::String(s) => Some(s.clone()),
        Value::Number(n) => Some(n.to_string()),
        Value::Bool(b) => Some(b.to_string()),
        _ => None,
    }
}

fn fields_of(content_type: Option<&str>, body: &[u8]) -> Result<Fields, MoRefusal> {
    let looks_json = body.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'{');
    let json = match content_type {
        Some(t) if t.to_ascii_lowercase().contains("json") => true,
        Some(t) if t.to_ascii_lowercase().contains("form-urlencoded") => false,
        _ => looks_json,
    };
    if json {
        let v: Value = serde_json::from_slice(body)
            .map_err(|e| MoRefusal::Malformed(format!("not JSON: {e}")))?;
        let Value::Object(map) = v else {
            return Err(MoRefusal::Malformed("the JSON is not an object".into()));
        };
        Ok(map
            .iter()
            .filter_map(|(k, v)| Some((k.clone(), json_text(v)?)))
            .collect())
    } else {
        let pairs: Vec<(String, String)> = serde_urlencoded::from_bytes(body)
            .map_err(|e| MoRefusal::Malformed(format!("not a form: {e}")))?;
        Ok(pairs.into_iter().collect())
    }
}

fn number<T: std::str::FromStr>(fields: &Fields, name: &str) -> Result<Option<T>, MoRefusal> {
    match fields.get(name).map(|s| s.trim()) {
        None | Some("") => Ok(None),
        Some(s) => s
            .parse()
            .map(Some)
            .map_err(|_| MoRefusal::Malformed(format!("{name} {s:?} is not a number"))),
    }
}

fn hex_data(text: &str, what: &str) -> Result<Vec<u8>, String> {
    // The service's documentation shows the hex in groups: spaces are
    // not part of the data.
    let compact: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    hex::decode(&compact).map_err(|e| format!("{what} is not hex: {e}"))
}

impl MoPost {
    /// Reads a post's body; `content_type` (the request's header) chooses
    /// form or JSON, and without it the body's first character does.
    pub fn parse(content_type: Option<&str>, body: &[u8]) -> Result<MoPost, MoRefusal> {
        let fields = fields_of(content_type, body)?;
        let imei = fields
            .get("imei")
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .ok_or_else(|| MoRefusal::Malformed("no imei".into()))?;
        let data = match fields.get("data") {
            Some(text) => hex_data(text, "data").map_err(MoRefusal::Malformed)?,
            None => Vec::new(),
        };
        Ok(MoPost {
            imei,
            momsn: number(&fields, "momsn")?,
            serial: number(&fields, "serial")?,
            transmit_time: fields.get("transmit_time").cloned(),
            iridium_latitude: number(&fields, "iridium_latitude")?,
            iridium_longitude: number(&fields, "iridium_longitude")?,
            iridium_cep: number(&fields, "iridium_cep")?,
            device_type: fields.get("device_type").cloned(),
            data,
            jwt: fields.get("JWT").cloned(),
        })
    }

    /// The fields as the token's claims carry them (every value a string).
    fn claim_fields(&self) -> Vec<(&'static str, String)> {
        let mut out = vec![("imei", self.imei.clone())];
        let mut opt = |name: &'static str, v: Option<String>| {
            if let Some(v) = v {
                out.push((name, v));
            }
        };
        opt("momsn", self.momsn.map(|n| n.to_string()));
        opt("serial", self.serial.map(|n| n.to_string()));
        opt("transmit_time", self.transmit_time.clone());
        opt(
            "iridium_latitude",
            self.iridium_latitude.map(|n| n.to_string()),
        );
        opt(
            "iridium_longitude",
            self.iridium_longitude.map(|n| n.to_string()),
        );
        opt("iridium_cep", self.iridium_cep.map(|n| n.to_string()));
        opt("device_type", self.device_type.clone());
        out.push(("data", hex::encode(&self.data)));
        out
    }

    /// The body in `format`, its token included when it has one (the
    /// service's side, for the emulator).
    pub fn to_body(&self, format: MoFormat) -> Vec<u8> {
        match format {
            MoFormat::Form => {
                let mut pairs = self.claim_fields();
                if let Some(jwt) = &self.jwt {
                    pairs.push(("JWT", jwt.clone()));
                }
                serde_urlencoded::to_string(pairs)
                    .unwrap_or_default()
                    .into_bytes()
            }
            MoFormat::Json => {
                let mut map = Map::new();
                map.insert("imei".into(), self.imei.clone().into());
                let mut put = |k: &str, v: Option<Value>| {
                    if let Some(v) = v {
                        map.insert(k.into(), v);
                    }
                };
                put("momsn", self.momsn.map(Value::from));
                put("serial", self.serial.map(Value::from));
                put("transmit_time", self.transmit_time.clone().map(Value::from));
                put("iridium_latitude", self.iridium_latitude.map(Value::from));
                put("iridium_longitude", self.iridium_longitude.map(Value::from));
                put("iridium_cep", self.iridium_cep.map(Value::from));
                put("device_type", self.device_type.clone().map(Value::from));
                put("data", Some(hex::encode(&self.data).into()));
                put("JWT", self.jwt.clone().map(Value::from));
                Value::Object(map).to_string().into_bytes()
            }
        }
    }
}

/// The library's crypto (pure-Rust RSA) for the process, unless another is
/// chosen already; `Err` when none can be had (never a panic).
fn crypto_ready() -> Result<(), String> {
    use jsonwebtoken::crypto::CryptoProvider;
    if CryptoProvider::try_get_default().is_none() {
        let _ = jsonwebtoken::crypto::rust_crypto::DEFAULT_PROVIDER.install_default();
    }
    CryptoProvider::try_get_default()
        .map(|_| ())
        .ok_or_else(|| "no JWT crypto provider".to_string())
}

/// Checks a post's token with the service's RSA public key (RS256 only:
/// a token of another algorithm, `none` included, is refused).
pub struct JwtVerifier {
    key: DecodingKey,
    validation: Validation,
}

impl fmt::Debug for JwtVerifier {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("JwtVerifier").finish_non_exhaustive()
    }
}

impl JwtVerifier {
    /// The verifier of the RSA public key in `pem` (`BEGIN PUBLIC KEY` or
    /// `BEGIN RSA PUBLIC KEY`); `Err` says why the key cannot be used.
    pub fn from_pem(pem: &[u8]) -> Result<JwtVerifier, String> {
        crypto_ready()?;
        let key = DecodingKey::from_rsa_pem(pem)
            .map_err(|e| format!("not an RSA public key in PEM: {e}"))?;
        let mut validation = Validation::new(Algorithm::RS256);
        validation.set_issuer(&[ISSUER]);
        // The service's tokens carry `iss` and `iat` only: no expiry, no
        // audience.
        validation.set_required_spec_claims(&["iss"]);
        validation.validate_exp = false;
        validation.validate_aud = false;
        Ok(JwtVerifier { key, validation })
    }

    /// Takes `post` when its token verifies and says what the post says.
    pub fn verify(&self, post: &MoPost) -> Result<(), MoRefusal> {
        let token = post.jwt.as_deref().ok_or(MoRefusal::NoToken)?;
        let claims: Map<String, Value> =
            jsonwebtoken::decode(token.trim(), &self.key, &self.validation)
                .map_err(|e| MoRefusal::BadToken(e.to_string()))?
                .claims;
        let claim = |name: &str| claims.get(name).and_then(json_text);
        let differs = |what: &str| {
            MoRefusal::BadToken(format!(
                "its {what} is not the post's (a token of another message?)"
            ))
        };
        if claim("imei").as_deref().map(str::trim) != Some(post.imei.as_str()) {
            return Err(differs("imei"));
        }
        let signed_data = hex_data(&claim("data").unwrap_or_default(), "its data")
            .map_err(MoRefusal::BadToken)?;
        if signed_data != post.data {
            return Err(differs("data"));
        }
        let signed_momsn = claim("momsn").and_then(|s| s.trim().parse::<u64>().ok());
        if post.momsn.is_some() && signed_momsn != post.momsn {
            return Err(differs("momsn"));
        }
        if let (Some(a), Some(b)) = (claim("transmit_time"), &post.transmit_time) {
            if a.trim() != b.trim() {
                return Err(differs("transmit_time"));
            }
        }
        Ok(())
    }
}

/// Signs posts as the service does (for the emulator and tests: RS256 with
/// an RSA private key).
pub struct JwtSigner {
    key: EncodingKey,
}

impl fmt::Debug for JwtSigner {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("JwtSigner").finish_non_exhaustive()
    }
}

impl JwtSigner {
    /// The signer of the RSA private key in `pem` (PKCS#1 or PKCS#8).
    pub fn from_pem(pem: &[u8]) -> Result<JwtSigner, String> {
        crypto_ready()?;
        let key = EncodingKey::from_rsa_pem(pem)
            .map_err(|e| format!("not an RSA private key in PEM: {e}"))?;
        Ok(JwtSigner { key })
    }

    /// The token of `post` issued at `iat` (Unix seconds), claims as the
    /// service's.
    pub fn token(&self, post: &MoPost, iat: u64) -> Result<String, String> {
        let mut claims = Map::new();
        claims.insert("iss".into(), ISSUER.into());
        claims.insert("iat".into(), iat.into());
        for (k, v) in post.claim_fields() {
            claims.insert(k.into(), v.into());
        }
        // The service's header is {"alg":"RS256"}, no type.
        let header = Header {
            typ: None,
            ..Header::new(Algorithm::RS256)
        };
        jsonwebtoken::encode(&header, &claims, &self.key).map_err(|e| e.to_string())
    }

    /// `post` with its token.
    pub fn sign(&self, mut post: MoPost, iat: u64) -> Result<MoPost, String> {
        post.jwt = Some(self.token(&post, iat)?);
        Ok(post)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The emulated service's key pair, for tests only (kept with the
    /// emulator).
    const TEST_PRIVATE_KEY_PEM: &str = include_str!(
        "../../../../emulators/src/iridium/test-key/rockblock-emulator-TEST-ONLY-private-key.pem"
    );
    const TEST_PUBLIC_KEY_PEM: &str = include_str!(
        "../../../../emulators/src/iridium/test-key/rockblock-emulator-TEST-ONLY-public-key.pem"
    );

    fn post() -> MoPost {
        MoPost {
            imei: "300234010753370".into(),
            momsn: Some(66),
            serial: Some(14331),
            transmit_time: Some("23-09-05 04:33:24".into()),
            iridium_latitude: Some(75.0001),
            iridium_longitude: Some(-154.1209),
            iridium_cep: Some(3.0),
            device_type: Some("ROCKBLOCK".into()),
            data: b"There are 10 types".to_vec(),
            jwt: None,
        }
    }

    fn keys() -> (JwtSigner, JwtVerifier) {
        (
            JwtSigner::from_pem(TEST_PRIVATE_KEY_PEM.as_bytes()).unwrap(),
            JwtVerifier::from_pem(TEST_PUBLIC_KEY_PEM.as_bytes()).unwrap(),
        )
    }

    #[test]
    fn posts_read_back_in_both_formats_and_verify() {
        let (signer, verifier) = keys();
        let signed = signer.sign(post(), 1_693_888_475).unwrap();
        for format in [MoFormat::Form, MoFormat::Json] {
            let body = signed.to_body(format);
            let read = MoPost::parse(Some(format.content_type()), &body).unwrap();
            assert_eq!(read, signed, "{format:?}");
            // Without a content type, the body tells.
            assert_eq!(MoPost::parse(None, &body).unwrap(), signed);
            verifier.verify(&read).unwrap();
        }
        // The service's documented JSON shape: numbers as numbers.
        let json: Value = serde_json::from_slice(&signed.to_body(MoFormat::Json)).unwrap();
        assert_eq!(json["momsn"], 66);
        assert_eq!(json["iridium_cep"], 3.0);
        assert_eq!(json["data"], hex::encode(b"There are 10 types"));
        // The token's claims are strings, and its header has no type.
        let token = signed.jwt.clone().unwrap();
        let claims: Map<String, Value> =
            jsonwebtoken::dangerous::insecure_decode_claims(&token).unwrap();
        assert_eq!(claims["iss"], "Rock 7");
        assert_eq!(claims["momsn"], "66");
        assert_eq!(claims["iridium_cep"], "3");
        let header = jsonwebtoken::decode_header(&token).unwrap();
        assert_eq!((header.alg, header.typ), (Algorithm::RS256, None));
    }

    #[test]
    fn forged_unsigned_and_altered_posts_are_refused() {
        let (signer, verifier) = keys();
        let signed = signer.sign(post(), 1).unwrap();
        // No token.
        assert_eq!(verifier.verify(&post()), Err(MoRefusal::NoToken));
        assert_eq!(MoRefusal::NoToken.http_status(), 401);
        // Garbage.
        let garbage = MoPost {
            jwt: Some("not.a.token".into()),
            ..post()
        };
        assert!(matches!(
            verifier.verify(&garbage),
            Err(MoRefusal::BadToken(_))
        ));
        // A valid token on other data.
        let altered = MoPost {
            data: b"other".to_vec(),
            ..signed.clone()
        };
        let e = verifier.verify(&altered).unwrap_err();
        assert!(e.to_string().contains("data"), "{e}");
        assert_eq!(e.http_status(), 403);
        for altered in [
            MoPost {
                imei: "300234010753371".into(),
                ..signed.clone()
            },
            MoPost {
                momsn: Some(67),
                ..signed.clone()
            },
            MoPost {
                transmit_time: Some("23-09-05 04:33:25".into()),
                ..signed.clone()
            },
        ] {
            assert!(verifier.verify(&altered).is_err(), "{altered:?}");
        }
        // Unsigned: alg none, and HS256 keyed with the public key's text.
        let b64 = |s: &str| {
            use base64::Engine;
            base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(s)
        };
        let claims = r#"{"iss":"Rock 7","imei":"300234010753370","data":"","momsn":"66"}"#;
        let none = format!("{}.{}.", b64(r#"{"alg":"none"}"#), b64(claims));
        let unsigned = MoPost {
            data: Vec::new(),
            jwt: Some(none),
            ..post()
        };
        assert!(matches!(
            verifier.verify(&unsigned),
            Err(MoRefusal::BadToken(_))
        ));
        let hs = jsonwebtoken::encode(
            &Header::new(Algorithm::HS256),
            &serde_json::from_str::<Value>(claims).unwrap(),
            &EncodingKey::from_secret(TEST_PUBLIC_KEY_PEM.as_bytes()).unwrap(),
        )
        .unwrap();
        let hs = MoPost {
            jwt: Some(hs),
            ..unsigned
        };
        assert!(matches!(verifier.verify(&hs), Err(MoRefusal::BadToken(_))));
        // Signed by another key: the test key's token against a verifier
        // of another public key.
        let other = JwtVerifier::from_pem(OTHER_PUBLIC_KEY.as_bytes()).unwrap();
        assert!(matches!(other.verify(&signed), Err(MoRefusal::BadToken(_))));
        // Another issuer.
        let mut claims: Map<String, Value> =
            jsonwebtoken::dangerous::insecure_decode_claims(signed.jwt.as_ref().unwrap()).unwrap();
        claims.insert("iss".into(), "someone".into());
        let header = Header {
            typ: None,
            ..Header::new(Algorithm::RS256)
        };
        let wrong_issuer = jsonwebtoken::encode(
            &header,
            &claims,
            &EncodingKey::from_rsa_pem(TEST_PRIVATE_KEY_PEM.as_bytes()).unwrap(),
        )
        .unwrap();
        let e = verifier
            .verify(&MoPost {
                jwt: Some(wrong_issuer),
                ..signed
            })
            .unwrap_err();
        assert!(e.to_string().to_lowercase().contains("issuer"), "{e}");
    }

    /// The public key of another test key pair: tokens of the test key
    /// fail against it.
    const OTHER_PUBLIC_KEY: &str = "-----BEGIN PUBLIC KEY-----
MIIBIjANBgkqhkiG9w0BAQEFAAOCAQ8AMIIBCgKCAQEAs94RpH5LywX7gY4KgDrB
7QNFneQEG7cpW6Y90pajrr6WyK0yJsoj7Q4Un7HkQF9PQ2oH/YzesWy9afwl1JtN
kIUiU3DKU29ZZmN8VCKhwEYp9ANrc4pYKl/E3VDZi07HYw8Kky6b+jpMVSs9afXl
rt0Z3hugtmWxIxVcbqaY2JBSraP/PlcgEoXbTZymZ2eA2RcHBxHtWQwtclgcGsbW
RbA+edGDpAHSTeAzRCnkVM+AP2aMONGKawuiza48dTmr5d/HnrlKiisLtxf3RvOC
zk0esQV+RZ4OGMX1uHTrINvH/QPfo1cmRdK1aOszNEwZ0UicDbSUM6FZYGdXIQbe
8QIDAQAB
-----END PUBLIC KEY-----
";

    #[test]
    fn malformed_posts_say_what_is_wrong() {
        for (ct, body, says) in [
            (Some("application/json"), &b"{"[..], "not JSON"),
            (Some("application/json"), b"[1]", "not an object"),
            (None, b"momsn=1&data=00", "no imei"),
            (None, b"imei=300234010753370&data=0g", "not hex"),
            (None, b"imei=300234010753370&momsn=x", "momsn"),
        ] {
            let e = MoPost::parse(ct, body).unwrap_err();
            assert_eq!(e.http_status(), 400);
            assert!(e.to_string().contains(says), "{e}");
        }
        // Hex in groups, as the service's documentation prints it.
        let p = MoPost::parse(None, b"imei=300234010753370&data=48656c6c6f20576f+726c64").unwrap();
        assert_eq!(p.data, b"Hello World");
    }
}
