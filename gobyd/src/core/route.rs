//! Static routes as Goby3 has them (`goby::acomms::RouteManager`): the
//! next node a message for a destination goes to, from a list of hops, a
//! subnet mask and a default gateway. Sans-IO: a table and a question.
//!
//! The rule, as Goby3's `find_next_hop`:
//!
//! - when this node and the destination are both on the route (the list of
//!   `hop`s), the next hop is this node's neighbour on the route towards the
//!   destination (the route is a line: each node hears the nodes next to it
//!   in the list);
//! - otherwise, the default gateway when there is one;
//! - otherwise none: the message goes straight to its destination.
//!
//! And Goby3's subnet rule: a next hop is reachable only on this node's
//! subnet (`id & subnet_mask`, by default `0xFFFFFF00`: modem ids 0-255 are
//! one subnet), the one its link reaches. That holds for a destination
//! reached straight too: one off this node's subnet that neither the route
//! nor a default gateway leads to has no route ([`NextHop::Unreachable`]).

use protos::goby::apps::protobuf::NetworkConfig;

use crate::config::Problem;

/// Largest modem id the network header carries on the water (8 bits).
pub const MAX_NETWORK_ID: i32 = 255;

/// Most relays a message may pass (the header's `hop` list holds 7).
pub const MAX_HOP_LIMIT: u32 = 7;

/// Where a message for a destination goes from this node.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NextHop {
    /// Straight to the destination (a neighbour, or no route says
    /// otherwise).
    Direct,
    /// To this relay first.
    Via(i32),
    /// Nowhere: the next hop the route gives, or the destination itself
    /// when nothing leads there, is off this node's subnet.
    Unreachable(String),
}

/// A node's static route.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RouteTable {
    me: i32,
    hops: Vec<i32>,
    subnet_mask: u32,
    default_gateway: Option<i32>,
}

impl RouteTable {
    /// The table of node `me` from the `network` section; the problems of
    /// its settings (each named by its field) when it has any.
    pub fn from_config(config: &NetworkConfig, me: i32) -> Result<Self, Vec<Problem>> {
        let table = RouteTable {
            me,
            hops: config
                .route
                .as_ref()
                .map(|r| r.hop.clone())
                .unwrap_or_default(),
            subnet_mask: config.subnet_mask(),
            default_gateway: config.default_gateway.map(|g| g as i32),
        };
        let problems = table.problems(config);
        if problems.is_empty() {
            Ok(table)
        } else {
            Err(problems)
        }
    }

    /// The route's hops, in order.
    pub fn hops(&self) -> &[i32] {
        &self.hops
    }

    fn problems(&self, config: &NetworkConfig) -> Vec<Problem> {
        let mut problems = Vec::new();
        if !(0..=MAX_NETWORK_ID).contains(&self.me) {
            problems.push(Problem::new(
                "modem_id",
                format!(
                    "{} is above {MAX_NETWORK_ID}, the largest modem id the network header carries (network section)",
                    self.me
                ),
            ));
        }
        for (i, &hop) in self.hops.iter().enumerate() {
            let field = format!("network.route.hop[{i}]");
            if !(0..=MAX_NETWORK_ID).contains(&hop) {
                problems.push(Problem::new(
                    field,
                    format!(
                        "{hop} is not a modem id the network header carries (0-{MAX_NETWORK_ID})"
                    ),
                ));
            } else if self.hops[..i].contains(&hop) {
                problems.push(Problem::new(
                    field,
                    format!("{hop} is on the route twice: a route is a line of distinct nodes"),
                ));
            }
        }
        if let Some(i) = self.hops.iter().position(|&h| h == self.me) {
            for j in [i.checked_sub(1), Some(i + 1)].into_iter().flatten() {
                if let Some(&neighbour) = self.hops.get(j) {
                    if !self.same_subnet(neighbour) {
                        problems.push(Problem::new(
                            format!("network.route.hop[{j}]"),
                            format!(
                                "{neighbour}, this node's neighbour on the route, is on subnet {:#x} \
                                 and this node ({}) on {:#x} (subnet_mask {:#x}): its link cannot reach it",
                                neighbour as u32 & self.subnet_mask,
                                self.me,
                                self.me as u32 & self.subnet_mask,
                                self.subnet_mask
                            ),
                        ));
                    }
                }
            }
        }
        if let Some(gateway) = self.default_gateway {
            if gateway == self.me {
                problems.push(Problem::new(
                    "network.default_gateway",
                    format!("{gateway} is this node: a gateway is another node"),
                ));
            } else if !(0..=MAX_NETWORK_ID).contains(&gateway) {
                problems.push(Problem::new(
                    "network.default_gateway",
                    format!("{gateway} is not a modem id the network header carries (0-{MAX_NETWORK_ID})"),
                ));
            } else if !self.same_subnet(gateway) {
                problems.push(Problem::new(
                    "network.default_gateway",
                    format!(
                        "{gateway} is not on this node's subnet {:#x} (subnet_mask {:#x})",
                        self.me as u32 & self.subnet_mask,
                        self.subnet_mask
                    ),
                ));
            }
        }
        let limit = config.hop_limit();
        if !(1..=MAX_HOP_LIMIT).contains(&limit) {
            problems.push(Problem::new(
                "network.hop_limit",
                format!("{limit} is not 1-{MAX_HOP_LIMIT} (the relays a message may pass)"),
            ));
        }
        problems
    }

    fn same_subnet(&self, id: i32) -> bool {
        id as u32 & self.subnet_mask == self.me as u32 & self.subnet_mask
    }

    fn index(&self, id: i32) -> Option<usize> {
        self.hops.iter().position(|&h| h == id)
    }

    /// Goby3's next hop from this node to `dest` (`None`: no route says,
    /// the message goes straight to `dest`).
    fn goby3_next_hop(&self, dest: i32) -> Option<i32> {
        let on_route = match (self.index(self.me), self.index(dest)) {
            (Some(here), Some(there)) => {
                let next = match there.cmp(&here) {
                    std::cmp::Ordering::Less => here - 1,
                    std::cmp::Ordering::Greater => here + 1,
                    std::cmp::Ordering::Equal => here,
                };
                self.hops.get(next).copied()
            }
            _ => None,
        };
        on_route.or(self.default_gateway)
    }

    /// Where a message for `dest` goes from this node. Broadcasts, and
    /// messages to this node, are never routed.
    pub fn next_hop(&self, dest: i32) -> NextHop {
        if dest == queue::BROADCAST_ID || dest == self.me {
            return NextHop::Direct;
        }
        let next = match self.goby3_next_hop(dest) {
            Some(next) if next != self.me => next,
            _ => dest,
        };
        if !self.same_subnet(next) {
            let (subnet, mine) = (
                next as u32 & self.subnet_mask,
                self.me as u32 & self.subnet_mask,
            );
            return NextHop::Unreachable(if next == dest {
                format!(
                    "no route to {dest}: it is on subnet {subnet:#x}, not this node's ({mine:#x}, \
                     subnet_mask {:#x}), and neither the route nor a default gateway leads there",
                    self.subnet_mask
                )
            } else {
                format!(
                    "the route's next hop towards {dest} is {next}, on subnet {subnet:#x}, not this node's ({mine:#x})"
                )
            });
        }
        if next == dest {
            NextHop::Direct
        } else {
            NextHop::Via(next)
        }
    }

    /// The node a message for `dest` is handed to: the relay, or `dest`
    /// itself.
    pub fn link_dest(&self, dest: i32) -> Result<i32, String> {
        match self.next_hop(dest) {
            NextHop::Direct => Ok(dest),
            NextHop::Via(relay) => Ok(relay),
            NextHop::Unreachable(reason) => Err(reason),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protos::goby::apps::protobuf::network_config::StaticRoute;

    fn table(me: i32, hops: &[i32], gateway: Option<u32>) -> RouteTable {
        let config = NetworkConfig {
            route: Some(StaticRoute { hop: hops.to_vec() }),
            default_gateway: gateway,
            ..Default::default()
        };
        RouteTable::from_config(&config, me).unwrap()
    }

    #[test]
    fn the_next_hop_is_the_neighbour_towards_the_destination() {
        // A line as Goby3's route1 test has: 4 - 1 - 2 - 3.
        let t = table(1, &[4, 1, 2, 3], None);
        assert_eq!(t.next_hop(3), NextHop::Via(2));
        assert_eq!(t.next_hop(2), NextHop::Direct);
        assert_eq!(t.next_hop(4), NextHop::Direct);
        // Off the route, no gateway: straight there; broadcasts and this
        // node are never routed.
        assert_eq!(t.next_hop(9), NextHop::Direct);
        assert_eq!(t.next_hop(0), NextHop::Direct);
        assert_eq!(t.next_hop(1), NextHop::Direct);
        let t = table(3, &[4, 1, 2, 3], None);
        assert_eq!(t.next_hop(4), NextHop::Via(2));
        assert_eq!(t.link_dest(1), Ok(2));
    }

    #[test]
    fn the_default_gateway_takes_what_the_route_does_not() {
        let t = table(1, &[1, 2, 3], Some(2));
        assert_eq!(t.next_hop(7), NextHop::Via(2));
        assert_eq!(t.next_hop(3), NextHop::Via(2));
        // Not on the route itself: everything goes to the gateway.
        let t = table(5, &[1, 2, 3], Some(2));
        assert_eq!(t.next_hop(3), NextHop::Via(2));
        assert_eq!(t.next_hop(2), NextHop::Direct);
        assert_eq!(t.next_hop(0), NextHop::Direct);
    }

    #[test]
    fn a_destination_off_the_subnet_that_nothing_leads_to_has_no_route() {
        let config = |gateway: Option<u32>| NetworkConfig {
            route: Some(StaticRoute { hop: vec![1, 2, 3] }),
            subnet_mask: Some(0xFFFF_FFF0),
            default_gateway: gateway,
            ..Default::default()
        };
        let t = RouteTable::from_config(&config(None), 1).unwrap();
        assert!(
            matches!(t.next_hop(20), NextHop::Unreachable(ref r) if r.contains("no route to 20") && r.contains("0x10")),
            "{:?}",
            t.next_hop(20)
        );
        assert!(t.link_dest(20).is_err());
        // On this node's subnet: straight there, as before; the route as before.
        assert_eq!(t.next_hop(9), NextHop::Direct);
        assert_eq!(t.next_hop(3), NextHop::Via(2));
        // A default gateway on the subnet leads there.
        let t = RouteTable::from_config(&config(Some(2)), 1).unwrap();
        assert_eq!(t.next_hop(20), NextHop::Via(2));
    }

    #[test]
    fn bad_routes_are_refused_naming_the_field() {
        let config = |hops: Vec<i32>, gateway: Option<u32>, limit: Option<u32>| NetworkConfig {
            route: Some(StaticRoute { hop: hops }),
            default_gateway: gateway,
            hop_limit: limit,
            ..Default::default()
        };
        let problems =
            RouteTable::from_config(&config(vec![1, 2, 1, 300], Some(1), Some(9)), 1).unwrap_err();
        let text: Vec<String> = problems.iter().map(|p| p.to_string()).collect();
        let all = text.join("\n");
        for part in [
            "network.route.hop[2]: 1 is on the route twice",
            "network.route.hop[3]: 300 is not a modem id",
            "network.default_gateway: 1 is this node",
            "network.hop_limit: 9 is not 1-7",
        ] {
            assert!(all.contains(part), "{part:?} missing from {all}");
        }
        // A neighbour on another subnet cannot be reached.
        let other = NetworkConfig {
            route: Some(StaticRoute {
                hop: vec![1, 2, 0x201],
            }),
            subnet_mask: Some(0xFFFF_FF00),
            ..Default::default()
        };
        let problems = RouteTable::from_config(&other, 2).unwrap_err();
        assert!(problems[0].to_string().contains("network.route.hop[2]"));
    }
}
