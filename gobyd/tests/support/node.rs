//! One builder for the text of a `gobyd` node configuration (protobuf text
//! format) as the integration tests write it: the node's id, its driver
//! (acoustic simulator, UDP or WHOI Micro-Modem), its MAC, its queue
//! entries, the JSON interface, the MQTT and MOOS sections, the data
//! directory, the log and any further text. A section not given is left
//! out of the text (the daemon's default applies).
//!
//! The text is checked with [`gobyd::config::parse`] as it is rendered: a
//! test whose configuration `gobyd` cannot read (an unknown field, a value
//! of the wrong type) fails at once, with the parser's message (line,
//! column and field) and the text.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use protos::goby::apps::protobuf::GobydConfig;

/// The configuration of node `modem_id`; see the [module](self) for what
/// it renders.
#[derive(Debug, Clone)]
pub struct Node {
    id: i32,
    driver: Option<Driver>,
    mac: Option<Mac>,
    entries: Vec<Entry>,
    queue_settings: Vec<String>,
    json_tcp: Option<String>,
    json_udp: Option<String>,
    mqtt: Option<String>,
    moos: Option<String>,
    data_dir: Option<PathBuf>,
    log_level: Option<String>,
    raw_log: Option<bool>,
    extra: Vec<String>,
    links: Vec<String>,
}

impl Node {
    /// Node `modem_id: id`, with no other section.
    pub fn new(id: i32) -> Node {
        Node {
            id,
            driver: None,
            mac: None,
            entries: Vec::new(),
            queue_settings: Vec::new(),
            json_tcp: None,
            json_udp: None,
            mqtt: None,
            moos: None,
            data_dir: None,
            log_level: None,
            raw_log: None,
            extra: Vec::new(),
            links: Vec::new(),
        }
    }

    /// A `link { name: "NAME" driver { … } mac { … } MORE }` section (a
    /// node of several links): its driver, fixed TDMA with one slot for each
    /// source in `srcs` at `rate` of `slot_seconds`, and `more` (text format
    /// fields of the section, e.g. `cost: 10 budget { bytes: 100 }`).
    pub fn link(
        mut self,
        name: &str,
        driver: impl Into<Driver>,
        srcs: &[i32],
        rate: u32,
        slot_seconds: f64,
        more: &str,
    ) -> Node {
        let mut text = format!("link {{\n  name: \"{name}\"\n");
        text += &driver.into().render();
        text += &Mac::Tdma {
            slots: srcs.iter().map(|&s| (s, String::new())).collect(),
            rate,
            slot_seconds,
        }
        .render();
        if !more.is_empty() {
            text += &format!("  {more}\n");
        }
        text += "}\n";
        self.links.push(text);
        self
    }

    /// The `driver { … }` section.
    pub fn driver(mut self, driver: impl Into<Driver>) -> Node {
        self.driver = Some(driver.into());
        self
    }

    /// `mac { type: MAC_NONE }`: the node never transmits.
    pub fn mac_none(mut self) -> Node {
        self.mac = Some(Mac::None);
        self
    }

    /// `mac { type: MAC_FIXED_DECENTRALIZED … }` with one slot for each
    /// source in `srcs`, in that order, each `slot { src: S dest: -1 rate:
    /// RATE slot_seconds: SLOT }` (`rate` the modem's rate number,
    /// `slot_seconds` the slot's length in seconds).
    pub fn tdma(mut self, srcs: &[i32], rate: u32, slot_seconds: f64) -> Node {
        self.mac = Some(Mac::Tdma {
            slots: srcs.iter().map(|&s| (s, String::new())).collect(),
            rate,
            slot_seconds,
        });
        self
    }

    /// As [`tdma`](Self::tdma), each slot a Flexible Data Protocol packet of
    /// the Micro-Modem 2 (`rate` 1, 3 or 5): `slot { src: S dest: -1 rate:
    /// RATE type: DRIVER_SPECIFIC micromodem { type: MICROMODEM_FLEXIBLE_DATA }
    /// slot_seconds: SLOT }`, or with Goby3's name for the settings
    /// (`[goby.acomms.micromodem.protobuf.transmission]`) when `goby3_name`.
    pub fn fdp_tdma(
        mut self,
        srcs: &[i32],
        rate: u32,
        slot_seconds: f64,
        goby3_name: bool,
    ) -> Node {
        self.mac = Some(Mac::Tdma {
            slots: srcs.iter().map(|&s| (s, fdp_kind(goby3_name))).collect(),
            rate,
            slot_seconds,
        });
        self
    }

    /// As [`tdma`](Self::tdma), with the slots `(src, fdp)` in that order,
    /// each a data slot or (`fdp`) a Flexible Data Protocol slot as
    /// [`fdp_tdma`](Self::fdp_tdma) writes them.
    pub fn mixed_tdma(mut self, slots: &[(i32, bool)], rate: u32, slot_seconds: f64) -> Node {
        self.mac = Some(Mac::Tdma {
            slots: slots
                .iter()
                .map(|&(s, fdp)| (s, if fdp { fdp_kind(false) } else { String::new() }))
                .collect(),
            rate,
            slot_seconds,
        });
        self
    }

    /// A field of the `queue { … }` section itself (e.g.
    /// `minimum_ack_wait_seconds: 30`), before its entries.
    pub fn queue_setting(mut self, text: &str) -> Node {
        self.queue_settings.push(text.to_string());
        self
    }

    /// A `message_entry { … }` of the `queue { … }` section, after those
    /// given before.
    pub fn queue(mut self, entry: Entry) -> Node {
        self.entries.push(entry);
        self
    }

    /// `json { tcp_bind: "ADDR" }`: the JSON interface over TCP on `addr`
    /// (`"127.0.0.1:0"` for a free port the daemon names in its log, `""`
    /// for none).
    pub fn json_tcp(mut self, addr: &str) -> Node {
        self.json_tcp = Some(addr.to_string());
        self
    }

    /// `udp_bind: "ADDR"` in the `json { … }` section: the JSON interface
    /// over UDP on `addr`.
    pub fn json_udp(mut self, addr: &str) -> Node {
        self.json_udp = Some(addr.to_string());
        self
    }

    /// `mqtt { broker: "BROKER" topic_prefix: "PREFIX" MORE }`: the bridge
    /// to the MQTT broker at `broker` (host:port), with `more` (text format
    /// fields of the section, e.g. `reconnect_max_seconds: 1`) added.
    pub fn mqtt(mut self, broker: &str, topic_prefix: &str, more: &str) -> Node {
        self.mqtt = Some(format!(
            "mqtt {{ broker: \"{broker}\" topic_prefix: \"{topic_prefix}\" {more} }}"
        ));
        self
    }

    /// `moos { server: "127.0.0.1" port: PORT MORE }`: a client of the
    /// MOOSDB on the loopback `port`, with `more` (text format fields of
    /// the section, e.g. `name: "gobyd1"`) added.
    pub fn moos(mut self, port: u16, more: &str) -> Node {
        self.moos = Some(format!(
            "moos {{ server: \"127.0.0.1\" port: {port} {more} }}"
        ));
        self
    }

    /// `data_dir: "DIR"`: the node's journal, inbox and mission log.
    pub fn data_dir(mut self, dir: &Path) -> Node {
        self.data_dir = Some(dir.to_path_buf());
        self
    }

    /// `level: "LEVEL"` in the `log { … }` section (e.g. `"info"`).
    pub fn log_level(mut self, level: &str) -> Node {
        self.log_level = Some(level.to_string());
        self
    }

    /// `raw_log: BOOL` in the `log { … }` section: whether the mission log
    /// records what the driver sends and receives.
    pub fn raw_log(mut self, raw: bool) -> Node {
        self.raw_log = Some(raw);
        self
    }

    /// A `mac_switcher { default_mac: "DEFAULT" mac { … } … }` section:
    /// for each `(name, rate, slot_seconds)` of `macs` a fixed TDMA MAC of
    /// one slot of this node, `slot { src: ID dest: -1 rate: RATE
    /// slot_seconds: SLOT }`.
    pub fn mac_switcher(self, default: &str, macs: &[(&str, u32, f64)]) -> Node {
        let id = self.id;
        let macs: String = macs
            .iter()
            .map(|(name, rate, seconds)| {
                format!(
                    " mac {{ name: \"{name}\" mac {{ type: MAC_FIXED_DECENTRALIZED \
                     slot {{ src: {id} dest: -1 rate: {rate} slot_seconds: {seconds} }} }} }}"
                )
            })
            .collect();
        self.extra(&format!(
            "mac_switcher {{ default_mac: \"{default}\"{macs} }}"
        ))
    }

    /// Text format fields added at the end, as they are (e.g. a
    /// `translator_entry { … }`); after those given before.
    pub fn extra(mut self, text: &str) -> Node {
        self.extra.push(text.to_string());
        self
    }

    /// The configuration's text, checked: panics with the parser's message
    /// (line, column and field) and the text when `gobyd` cannot read it.
    pub fn text(&self) -> String {
        self.checked().0
    }

    /// The configuration, parsed (for a daemon started in-process); panics
    /// as [`text`](Self::text) does.
    pub fn config(&self) -> GobydConfig {
        self.checked().1
    }

    /// Writes the checked [`text`](Self::text) to `path`; returns `path`.
    pub fn write(&self, path: impl AsRef<Path>) -> PathBuf {
        let path = path.as_ref();
        std::fs::write(path, self.text()).unwrap();
        path.to_path_buf()
    }

    /// The text and what `gobyd` reads from it; panics when it cannot.
    fn checked(&self) -> (String, GobydConfig) {
        let text = self.render();
        let origin = format!("node {} test configuration", self.id);
        match gobyd::config::parse(&text, &origin) {
            Ok(config) => (text, config),
            Err(e) => panic!("the test's gobyd configuration is refused: {e}\n{text}"),
        }
    }

    fn render(&self) -> String {
        let mut text = format!("modem_id: {}\n", self.id);
        if let Some(driver) = &self.driver {
            text += &driver.render();
        }
        if let Some(mac) = &self.mac {
            text += &mac.render();
        }
        for link in &self.links {
            text += link;
        }
        if !self.entries.is_empty() || !self.queue_settings.is_empty() {
            text += "queue {\n";
            for setting in &self.queue_settings {
                text += &format!("  {setting}\n");
            }
            for entry in &self.entries {
                text += &entry.render();
            }
            text += "}\n";
        }
        if self.json_tcp.is_some() || self.json_udp.is_some() {
            text += "json {";
            if let Some(addr) = &self.json_tcp {
                text += &format!(" tcp_bind: \"{addr}\"");
            }
            if let Some(addr) = &self.json_udp {
                text += &format!(" udp_bind: \"{addr}\"");
            }
            text += " }\n";
        }
        for section in [&self.mqtt, &self.moos].into_iter().flatten() {
            text += section;
            text += "\n";
        }
        if let Some(dir) = &self.data_dir {
            text += &format!("data_dir: \"{}\"\n", dir.display());
        }
        if self.log_level.is_some() || self.raw_log.is_some() {
            text += "log {";
            if let Some(level) = &self.log_level {
                text += &format!(" level: \"{level}\"");
            }
            if let Some(raw) = self.raw_log {
                text += &format!(" raw_log: {raw}");
            }
            text += " }\n";
        }
        for extra in &self.extra {
            text += extra;
            text += "\n";
        }
        text
    }
}

/// The MAC section of a [`Node`].
#[derive(Debug, Clone)]
enum Mac {
    None,
    Tdma {
        /// Each slot's source, and the text after its rate (its type and
        /// settings).
        slots: Vec<(i32, String)>,
        rate: u32,
        slot_seconds: f64,
    },
}

/// The text after a Flexible Data Protocol slot's rate, with Goby3's name
/// for its settings when `goby3_name`.
fn fdp_kind(goby3_name: bool) -> String {
    let name = if goby3_name {
        "[goby.acomms.micromodem.protobuf.transmission]"
    } else {
        "micromodem"
    };
    format!(" type: DRIVER_SPECIFIC {name} {{ type: MICROMODEM_FLEXIBLE_DATA }}")
}

impl Mac {
    fn render(&self) -> String {
        match self {
            Mac::None => "mac { type: MAC_NONE }\n".into(),
            Mac::Tdma {
                slots,
                rate,
                slot_seconds,
            } => {
                let mut text = "mac {\n  type: MAC_FIXED_DECENTRALIZED\n".to_string();
                for (src, kind) in slots {
                    text += &format!(
                        "  slot {{ src: {src} dest: -1 rate: {rate}{kind} slot_seconds: {slot_seconds} }}\n"
                    );
                }
                text += "}\n";
                text
            }
        }
    }
}

/// One `message_entry { … }` of the queue section.
#[derive(Debug, Clone)]
pub struct Entry {
    name: String,
    ack: Option<bool>,
    ttl: Option<u32>,
    roles: Vec<(String, String)>,
    extra: Vec<String>,
}

impl Entry {
    /// `message_entry { protobuf_name: "NAME" }`, no other field.
    pub fn new(protobuf_name: &str) -> Entry {
        Entry {
            name: protobuf_name.to_string(),
            ack: None,
            ttl: None,
            roles: Vec::new(),
            extra: Vec::new(),
        }
    }

    /// `goby.example.Command`, addressed by its `destination` field
    /// (`role { type: DESTINATION_ID field: "destination" }`).
    pub fn command() -> Entry {
        Entry::new("goby.example.Command").role("DESTINATION_ID", "destination")
    }

    /// `ack: BOOL`: whether the receiver acknowledges the message.
    pub fn ack(mut self, ack: bool) -> Entry {
        self.ack = Some(ack);
        self
    }

    /// `ttl: SECONDS`: how long a queued message waits to be sent.
    pub fn ttl(mut self, seconds: u32) -> Entry {
        self.ttl = Some(seconds);
        self
    }

    /// `role { type: KIND field: "FIELD" }` (`kind` e.g. `SOURCE_ID`,
    /// `DESTINATION_ID`), after those given before.
    pub fn role(mut self, kind: &str, field: &str) -> Entry {
        self.roles.push((kind.to_string(), field.to_string()));
        self
    }

    /// Text format fields of the entry added as they are (e.g.
    /// `max_queue: 100`).
    pub fn text(mut self, text: &str) -> Entry {
        self.extra.push(text.to_string());
        self
    }

    fn render(&self) -> String {
        let mut text = format!("  message_entry {{\n    protobuf_name: \"{}\"\n", self.name);
        if let Some(ack) = self.ack {
            text += &format!("    ack: {ack}\n");
        }
        if let Some(ttl) = self.ttl {
            text += &format!("    ttl: {ttl}\n");
        }
        for (kind, field) in &self.roles {
            text += &format!("    role {{ type: {kind} field: \"{field}\" }}\n");
        }
        for extra in &self.extra {
            text += &format!("    {extra}\n");
        }
        text += "  }\n";
        text
    }
}

/// The `driver { … }` section of a [`Node`].
#[derive(Debug, Clone)]
pub enum Driver {
    /// `DRIVER_ACOUSTIC_SIMULATOR`.
    Simulator(Simulator),
    /// `DRIVER_UDP`.
    Udp(Udp),
    /// `DRIVER_WHOI_MICROMODEM`.
    MicroModem(MicroModem),
    /// `DRIVER_UDP_MULTICAST`.
    Multicast(Multicast),
    /// `driver_name: "EVOLOGICS_S2C"`.
    Evologics(Evologics),
    /// `DRIVER_IRIDIUM` or `DRIVER_IRIDIUM_SHORE`.
    Iridium(Iridium),
    /// A `driver { … }` section written out whole.
    Text(String),
}

impl Driver {
    fn render(&self) -> String {
        match self {
            Driver::Simulator(s) => s.render(),
            Driver::Udp(u) => u.render(),
            Driver::MicroModem(m) => m.render(),
            Driver::Multicast(m) => m.render(),
            Driver::Evologics(e) => e.render(),
            Driver::Iridium(i) => i.render(),
            Driver::Text(t) => t.clone(),
        }
    }
}

impl From<Simulator> for Driver {
    fn from(s: Simulator) -> Driver {
        Driver::Simulator(s)
    }
}

impl From<Udp> for Driver {
    fn from(u: Udp) -> Driver {
        Driver::Udp(u)
    }
}

impl From<MicroModem> for Driver {
    fn from(m: MicroModem) -> Driver {
        Driver::MicroModem(m)
    }
}

/// The acoustic channel simulator driver: `driver { driver_type:
/// DRIVER_ACOUSTIC_SIMULATOR simulator { … } }`. Positions in metres.
#[derive(Debug, Clone)]
pub struct Simulator {
    nodes: Vec<String>,
    deferred_ack: bool,
    packet_overhead_seconds: Option<f64>,
    packet_loss: Option<f64>,
    seed: Option<u64>,
    channel: Option<String>,
    udp: Option<(i32, [u16; 2])>,
    range: Option<f64>,
    mesh: Option<(i32, Vec<u16>)>,
}

impl Simulator {
    fn with_nodes(nodes: Vec<String>) -> Simulator {
        Simulator {
            nodes,
            deferred_ack: false,
            packet_overhead_seconds: None,
            packet_loss: None,
            seed: None,
            channel: None,
            udp: None,
            range: None,
            mesh: None,
        }
    }

    /// Nodes 1 to `n` on a line, `spacing` metres apart along x: `node {
    /// modem_id: I x: (I-1)*SPACING }`.
    pub fn line(n: i32, spacing: f64) -> Simulator {
        Simulator::with_nodes(
            (1..=n)
                .map(|i| format!("node {{ modem_id: {i} x: {} }}", f64::from(i - 1) * spacing))
                .collect(),
        )
    }

    /// `range`: the farthest a packet is heard, metres.
    pub fn range(mut self, metres: f64) -> Simulator {
        self.range = Some(metres);
        self
    }

    /// Node `id` of nodes 1 to `ports.len()`, each in its own process,
    /// the packets to every other over UDP on 127.0.0.1 (node I on
    /// `ports[I-1]`; who hears whom is the channel's business, e.g. its
    /// `range`).
    pub fn mesh(mut self, id: i32, ports: &[u16]) -> Simulator {
        self.mesh = Some((id, ports.to_vec()));
        self
    }

    /// Node 1 alone, at no given position: `node { modem_id: 1 }`.
    pub fn alone() -> Simulator {
        Simulator::with_nodes(vec!["node { modem_id: 1 }".into()])
    }

    /// Nodes 1 and 2, `spacing` metres apart along x: `node { modem_id: 1
    /// x: 0 }`, `node { modem_id: 2 x: SPACING }`.
    pub fn pair(spacing: f64) -> Simulator {
        Simulator::with_nodes(vec![
            "node { modem_id: 1 x: 0 }".into(),
            format!("node {{ modem_id: 2 x: {spacing} }}"),
        ])
    }

    /// Nodes 1 and 2, `spacing` metres apart along x, both at `z` metres:
    /// `node { modem_id: 1 x: 0 y: 0 z: Z }`, `node { modem_id: 2 x:
    /// SPACING y: 0 z: Z }`.
    pub fn pair_at(spacing: f64, z: f64) -> Simulator {
        Simulator::with_nodes(vec![
            format!("node {{ modem_id: 1 x: 0 y: 0 z: {z} }}"),
            format!("node {{ modem_id: 2 x: {spacing} y: 0 z: {z} }}"),
        ])
    }

    /// `deferred_ack: true` in the driver section: the daemon, not the
    /// driver, says when a received transmission is acknowledged.
    pub fn deferred_ack(mut self) -> Simulator {
        self.deferred_ack = true;
        self
    }

    /// `packet_overhead_seconds`: time on the water added to every packet.
    pub fn overhead(mut self, seconds: f64) -> Simulator {
        self.packet_overhead_seconds = Some(seconds);
        self
    }

    /// `packet_loss`: the chance (0 to 1) that a packet is lost.
    pub fn loss(mut self, chance: f64) -> Simulator {
        self.packet_loss = Some(chance);
        self
    }

    /// `seed` of the simulator's random losses.
    pub fn seed(mut self, seed: u64) -> Simulator {
        self.seed = Some(seed);
        self
    }

    /// `channel`: the name of the in-process channel the node is on.
    pub fn channel(mut self, name: &str) -> Simulator {
        self.channel = Some(name.to_string());
        self
    }

    /// Node `id` of the two (1 or 2) in its own process, the packets to
    /// the other over UDP on 127.0.0.1: `udp_local { modem_id: ID port:
    /// PORTS[ID-1] }`, `udp_peer { modem_id: OTHER ip: "127.0.0.1" port:
    /// PORTS[OTHER-1] }`.
    pub fn between_processes(mut self, id: i32, ports: [u16; 2]) -> Simulator {
        self.udp = Some((id, ports));
        self
    }

    fn render(&self) -> String {
        let mut text = "driver {\n  driver_type: DRIVER_ACOUSTIC_SIMULATOR\n".to_string();
        if self.deferred_ack {
            text += "  deferred_ack: true\n";
        }
        text += "  simulator {\n";
        for node in &self.nodes {
            text += &format!("    {node}\n");
        }
        if let Some(seconds) = self.packet_overhead_seconds {
            text += &format!("    packet_overhead_seconds: {seconds}\n");
        }
        if let Some(chance) = self.packet_loss {
            text += &format!("    packet_loss: {chance}\n");
        }
        if let Some(seed) = self.seed {
            text += &format!("    seed: {seed}\n");
        }
        if let Some(channel) = &self.channel {
            text += &format!("    channel: \"{channel}\"\n");
        }
        if let Some(range) = self.range {
            text += &format!("    range: {range}\n");
        }
        if let Some((id, ports)) = &self.mesh {
            for (i, port) in ports.iter().enumerate() {
                let node = i as i32 + 1;
                if node == *id {
                    text += &format!("    udp_local {{ modem_id: {node} port: {port} }}\n");
                } else {
                    text += &format!(
                        "    udp_peer {{ modem_id: {node} ip: \"127.0.0.1\" port: {port} }}\n"
                    );
                }
            }
        }
        if let Some((id, ports)) = self.udp {
            let other = 3 - id;
            text += &format!(
                "    udp_local {{ modem_id: {id} port: {} }}\n",
                ports[(id - 1) as usize]
            );
            text += &format!(
                "    udp_peer {{ modem_id: {other} ip: \"127.0.0.1\" port: {} }}\n",
                ports[(other - 1) as usize]
            );
        }
        text += "  }\n}\n";
        text
    }
}

/// The UDP driver: `driver { driver_type: DRIVER_UDP udp { … } }`, on
/// 127.0.0.1.
#[derive(Debug, Clone)]
pub struct Udp {
    port: u16,
    remote: Option<(i32, u16)>,
    max_frame_size: Option<u32>,
}

impl Udp {
    /// `udp { local { port: PORT } }`: datagrams received on `port`.
    pub fn new(port: u16) -> Udp {
        Udp {
            port,
            remote: None,
            max_frame_size: None,
        }
    }

    /// Node `id` of two (1 or 2): received on `ports[id-1]`, sent to the
    /// other node on its port.
    pub fn pair(id: i32, ports: [u16; 2]) -> Udp {
        let other = 3 - id;
        Udp::new(ports[(id - 1) as usize]).remote(other, ports[(other - 1) as usize])
    }

    /// `remote { modem_id: ID ip: "127.0.0.1" port: PORT }`: where node
    /// `modem_id`'s datagrams go.
    pub fn remote(mut self, modem_id: i32, port: u16) -> Udp {
        self.remote = Some((modem_id, port));
        self
    }

    /// `max_frame_size`: the largest frame, in bytes.
    pub fn max_frame_size(mut self, bytes: u32) -> Udp {
        self.max_frame_size = Some(bytes);
        self
    }

    fn render(&self) -> String {
        let mut text = format!(
            "driver {{\n  driver_type: DRIVER_UDP\n  udp {{\n    local {{ port: {} }}\n",
            self.port
        );
        if let Some((modem_id, port)) = self.remote {
            text +=
                &format!("    remote {{ modem_id: {modem_id} ip: \"127.0.0.1\" port: {port} }}\n");
        }
        if let Some(bytes) = self.max_frame_size {
            text += &format!("    max_frame_size: {bytes}\n");
        }
        text += "  }\n}\n";
        text
    }
}

/// The UDP multicast driver on the loopback interface: `driver {
/// driver_type: DRIVER_UDP_MULTICAST udp_multicast { multicast_address
/// multicast_port interface_address: "127.0.0.1" } }`.
#[derive(Debug, Clone)]
pub struct Multicast {
    group: String,
    port: u16,
}

impl Multicast {
    /// A member of `group` (e.g. 239.255.1.1) on `port`, on 127.0.0.1.
    pub fn new(group: &str, port: u16) -> Multicast {
        Multicast {
            group: group.to_string(),
            port,
        }
    }

    fn render(&self) -> String {
        format!(
            "driver {{\n  driver_type: DRIVER_UDP_MULTICAST\n  udp_multicast {{\n    multicast_address: \"{}\"\n    multicast_port: {}\n    interface_address: \"127.0.0.1\"\n  }}\n}}\n",
            self.group, self.port
        )
    }
}

impl From<Multicast> for Driver {
    fn from(m: Multicast) -> Driver {
        Driver::Multicast(m)
    }
}

/// The WHOI Micro-Modem driver: `driver { driver_type:
/// DRIVER_WHOI_MICROMODEM serial_port: "PORT" … }`.
#[derive(Debug, Clone)]
pub struct MicroModem {
    serial_port: PathBuf,
    serial_baud: Option<u32>,
    settings: Vec<String>,
}

impl MicroModem {
    /// The modem on the serial device (or pseudo-terminal link) at `path`.
    pub fn new(path: &Path) -> MicroModem {
        MicroModem {
            serial_port: path.to_path_buf(),
            serial_baud: None,
            settings: Vec::new(),
        }
    }

    /// `serial_baud`, in bit/s.
    pub fn baud(mut self, baud: u32) -> MicroModem {
        self.serial_baud = Some(baud);
        self
    }

    /// A field of the `micromodem { … }` block, in text format (e.g.
    /// `reconnect_interval_ms: 300`), after those given before.
    pub fn setting(mut self, field: &str) -> MicroModem {
        self.settings.push(field.to_string());
        self
    }

    /// `use_application_acks: BOOL` in the `micromodem { … }` block: acks
    /// from the daemon once its inbox holds a message (`true`), or from
    /// the modem on decode (`false`).
    pub fn use_application_acks(self, on: bool) -> MicroModem {
        self.setting(&format!("use_application_acks: {on}"))
    }

    fn render(&self) -> String {
        let mut text = format!(
            "driver {{\n  driver_type: DRIVER_WHOI_MICROMODEM\n  serial_port: \"{}\"\n",
            self.serial_port.display()
        );
        if let Some(baud) = self.serial_baud {
            text += &format!("  serial_baud: {baud}\n");
        }
        if !self.settings.is_empty() {
            text += &format!("  micromodem {{ {} }}\n", self.settings.join("  "));
        }
        text += "}\n";
        text
    }
}

impl From<Iridium> for Driver {
    fn from(i: Iridium) -> Driver {
        Driver::Iridium(i)
    }
}

impl From<Evologics> for Driver {
    fn from(e: Evologics) -> Driver {
        Driver::Evologics(e)
    }
}

/// The EvoLogics S2C driver of a node, reaching its modem over TCP on
/// 127.0.0.1.
#[derive(Debug, Clone)]
pub struct Evologics {
    port: u16,
    settings: Vec<String>,
}

impl Evologics {
    /// The modem serving its AT interface on 127.0.0.1:`port`.
    pub fn tcp(port: u16) -> Evologics {
        Evologics {
            port,
            settings: Vec::new(),
        }
    }

    /// A field of the `evologics { … }` block, in text format (e.g.
    /// `delivery_timeout_ms: 5000`), after those given before.
    pub fn setting(mut self, field: &str) -> Evologics {
        self.settings.push(field.to_string());
        self
    }

    fn render(&self) -> String {
        let mut text = format!(
            "driver {{\n  driver_name: \"EVOLOGICS_S2C\"\n  connection_type: CONNECTION_TCP_AS_CLIENT\n  tcp_server: \"127.0.0.1\"\n  tcp_port: {}\n",
            self.port
        );
        if !self.settings.is_empty() {
            text += &format!("  evologics {{ {} }}\n", self.settings.join("  "));
        }
        text += "}\n";
        text
    }
}

/// An Iridium driver: the vehicle's (`driver { driver_type: DRIVER_IRIDIUM
/// serial_port: "PORT" iridium { device: DEVICE_IRIDIUM_9602_9603 … } }`)
/// or the shore's (`DRIVER_IRIDIUM_SHORE`, DirectIP on 127.0.0.1).
#[derive(Debug, Clone)]
pub struct Iridium {
    kind: IridiumKind,
    settings: Vec<String>,
    device: String,
    shore_iridium: Vec<String>,
}

#[derive(Debug, Clone)]
enum IridiumKind {
    Vehicle(PathBuf),
    Shore {
        mo_port: u16,
        mt_port: u16,
        vehicles: Vec<(i32, String)>,
    },
    Rockblock {
        webhook_port: u16,
        server: String,
        key_file: Option<PathBuf>,
        vehicles: Vec<(i32, String)>,
    },
}

impl Iridium {
    /// The vehicle's driver on the transceiver at `path` (a 9603).
    pub fn vehicle(path: &Path) -> Iridium {
        Iridium {
            kind: IridiumKind::Vehicle(path.to_path_buf()),
            settings: Vec::new(),
            device: "DEVICE_IRIDIUM_9602_9603".into(),
            shore_iridium: Vec::new(),
        }
    }

    /// The shore's driver: MO listener on `mo_port`, the gateway's MT
    /// listener on `mt_port`, each vehicle's modem id and IMEI (9603s).
    pub fn shore(mo_port: u16, mt_port: u16, vehicles: &[(i32, &str)]) -> Iridium {
        Iridium {
            kind: IridiumKind::Shore {
                mo_port,
                mt_port,
                vehicles: vehicles
                    .iter()
                    .map(|(id, imei)| (*id, imei.to_string()))
                    .collect(),
            },
            settings: Vec::new(),
            device: "DEVICE_IRIDIUM_9602_9603".into(),
            shore_iridium: Vec::new(),
        }
    }

    /// The shore's driver over the RockBLOCK web service: its webhook on
    /// `webhook_port` (path `/`), the service's MT endpoint at `server`
    /// (account `user`/`pass`), the JWT key in `key_file` (`None`: JWT
    /// check off), each vehicle's modem id and IMEI.
    pub fn rockblock_shore(
        webhook_port: u16,
        server: &str,
        key_file: Option<&Path>,
        vehicles: &[(i32, &str)],
    ) -> Iridium {
        Iridium {
            kind: IridiumKind::Rockblock {
                webhook_port,
                server: server.to_string(),
                key_file: key_file.map(Path::to_path_buf),
                vehicles: vehicles
                    .iter()
                    .map(|(id, imei)| (*id, imei.to_string()))
                    .collect(),
            },
            settings: Vec::new(),
            device: "DEVICE_IRIDIUM_9602_9603".into(),
            shore_iridium: Vec::new(),
        }
    }

    /// A field of the `iridium { … }` (or `iridium_shore { … }`) block, in
    /// text format (e.g. `retry_backoff_ms: 200`).
    pub fn setting(mut self, field: &str) -> Iridium {
        self.settings.push(field.to_string());
        self
    }

    /// The transceivers' kind (`device: …`), a 9602/9603 unless told.
    pub fn device(mut self, device: &str) -> Iridium {
        self.device = device.to_string();
        self
    }

    /// A field of the shore driver's `iridium { … }` block (its call
    /// timers), in text format.
    pub fn shore_iridium(mut self, field: &str) -> Iridium {
        self.shore_iridium.push(field.to_string());
        self
    }

    fn render(&self) -> String {
        let extra = self.settings.join(" ");
        let close = if self.shore_iridium.is_empty() {
            "  }\n}\n".to_string()
        } else {
            format!(
                "  }}\n  iridium {{ {} }}\n}}\n",
                self.shore_iridium.join(" ")
            )
        };
        match &self.kind {
            IridiumKind::Vehicle(path) => format!(
                "driver {{\n  driver_type: DRIVER_IRIDIUM\n  serial_port: \"{}\"\n  iridium {{ device: {} {extra} }}\n}}\n",
                path.display(),
                self.device
            ),
            IridiumKind::Shore {
                mo_port,
                mt_port,
                vehicles,
            } => {
                let mut text = format!(
                    "driver {{\n  driver_type: DRIVER_IRIDIUM_SHORE\n  iridium_shore {{\n    \
                     mo_sbd_server_address: \"127.0.0.1\" mo_sbd_server_port: {mo_port}\n    \
                     mt_sbd_server_address: \"127.0.0.1\" mt_sbd_server_port: {mt_port}\n    \
                     device: {}\n",
                    self.device
                );
                for (id, imei) in vehicles {
                    text += &format!("    modem_id_to_imei {{ modem_id: {id} imei: \"{imei}\" }}\n");
                }
                if !extra.is_empty() {
                    text += &format!("    {extra}\n");
                }
                text += &close;
                text
            }
            IridiumKind::Rockblock {
                webhook_port,
                server,
                key_file,
                vehicles,
            } => {
                let mut text = format!(
                    "driver {{\n  driver_type: DRIVER_IRIDIUM_SHORE\n  iridium_shore {{\n    \
                     sbd_type: SBD_ROCKBLOCK\n    \
                     mo_sbd_server_address: \"127.0.0.1\" mo_sbd_server_port: {webhook_port}\n    \
                     rockblock {{ username: \"user\" password: \"pass\" server: \"{server}\" \
                     {} mt_retry_backoff_ms: 300 mt_attempts: 5 }}\n",
                    match key_file {
                        Some(k) => format!("jwt_public_key_file: \"{}\"", k.display()),
                        None => "skip_jwt_verification: true".into(),
                    }
                );
                for (id, imei) in vehicles {
                    text += &format!("    modem_id_to_imei {{ modem_id: {id} imei: \"{imei}\" }}\n");
                }
                if !extra.is_empty() {
                    text += &format!("    {extra}\n");
                }
                text += &close;
                text
            }
        }
    }
}
