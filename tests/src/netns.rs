//! A private network of Linux network namespaces for cluster tests: one
//! namespace per host, each joined to a bridge by a veth pair, so every
//! process has an address of its own and a link the test can cut. The
//! test process joins the bridge too (one veth in its own namespace), to
//! upload, submit and watch. Nothing leaves the machine: the subnet is
//! not routed anywhere. Needs root (`ip netns`, from iproute2).

use std::process::{Command, Output};

/// A bridge in a namespace of its own and the hosts on it; deleted (with
/// the test process's veth) when dropped.
#[derive(Debug)]
pub struct TestNet {
    /// Names start with this (unique per test process).
    prefix: String,
    /// The namespace that holds the bridge.
    switch: String,
    /// The test process's end of its veth, in its own namespace.
    own_link: String,
    /// The subnet's first three octets (one per test process, so two
    /// never share a route); hosts are `.1` upwards, the test process
    /// `.254`.
    subnet: String,
    hosts: Vec<Host>,
}

/// A host of a [`TestNet`]: a namespace with one address.
#[derive(Debug, Clone)]
pub struct Host {
    /// The namespace's name.
    pub ns: String,
    /// Its address on the bridge.
    pub addr: String,
    /// Its veth's end on the bridge (in the switch namespace).
    port: String,
}

/// Runs `ip ARGS`; panics with what it said when it fails.
fn ip(args: &[&str]) -> Output {
    let out = Command::new("ip")
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run ip (iproute2): {e}"));
    assert!(
        out.status.success(),
        "ip {}: {}; the cluster test needs root and iproute2 (ip netns)",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A `10.231.X` subnet no route of this namespace uses yet (a run that
/// was killed may have left its veth behind), starting from one derived
/// from the process id.
fn free_subnet() -> String {
    let start = std::process::id() % 250;
    (0..250)
        .map(|i| format!("10.231.{}", (start + i) % 250))
        .find(|net| {
            Command::new("ip")
                .args(["route", "show", &format!("{net}.0/24")])
                .output()
                .is_ok_and(|o| o.stdout.is_empty())
        })
        .expect("a free 10.231.X.0/24 subnet")
}

impl TestNet {
    /// Makes the bridge and joins the test process to it.
    pub fn new() -> Self {
        let prefix = format!("aob{}", std::process::id());
        let switch = format!("{prefix}-sw");
        ip(&["netns", "add", &switch]);
        let net = Self {
            own_link: format!("{prefix}t"),
            subnet: free_subnet(),
            prefix,
            switch,
            hosts: Vec::new(),
        };
        let sw = net.switch.as_str();
        ip(&["-n", sw, "link", "add", "br0", "type", "bridge"]);
        ip(&["-n", sw, "link", "set", "br0", "up"]);
        ip(&["-n", sw, "link", "set", "lo", "up"]);
        // The test process's own veth: this end stays here, the other
        // joins the bridge.
        ip(&[
            "link",
            "add",
            &net.own_link,
            "type",
            "veth",
            "peer",
            "name",
            "test",
            "netns",
            sw,
        ]);
        ip(&["-n", sw, "link", "set", "test", "master", "br0", "up"]);
        ip(&[
            "addr",
            "add",
            &format!("{}.254/24", net.subnet),
            "dev",
            &net.own_link,
        ]);
        ip(&["link", "set", &net.own_link, "up"]);
        net
    }

    /// Adds a host named `name` with the next address.
    pub fn host(&mut self, name: &str) -> Host {
        let n = self.hosts.len() + 1;
        let host = Host {
            ns: format!("{}-{name}", self.prefix),
            addr: format!("{}.{n}", self.subnet),
            port: format!("p{n}"),
        };
        let sw = self.switch.as_str();
        ip(&["netns", "add", &host.ns]);
        ip(&["-n", &host.ns, "link", "set", "lo", "up"]);
        ip(&[
            "-n", sw, "link", "add", &host.port, "type", "veth", "peer", "name", "eth0", "netns",
            &host.ns,
        ]);
        ip(&["-n", sw, "link", "set", &host.port, "master", "br0", "up"]);
        ip(&[
            "-n",
            &host.ns,
            "addr",
            "add",
            &format!("{}/24", host.addr),
            "dev",
            "eth0",
        ]);
        ip(&["-n", &host.ns, "link", "set", "eth0", "up"]);
        self.hosts.push(host.clone());
        host
    }

    /// Cuts `host`'s link: its packets go nowhere (its processes live on).
    pub fn cut(&self, host: &Host) {
        ip(&["-n", &self.switch, "link", "set", &host.port, "down"]);
    }
}

impl Default for TestNet {
    fn default() -> Self {
        Self::new()
    }
}

impl Host {
    /// `program` to run in this host's namespace.
    pub fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.ns]).arg(program);
        c
    }
}

impl Drop for TestNet {
    fn drop(&mut self) {
        // Processes still inside keep a namespace alive but nameless; the
        // veths go with their namespaces.
        let _ = Command::new("ip")
            .args(["link", "del", &self.own_link])
            .output();
        for h in &self.hosts {
            let _ = Command::new("ip").args(["netns", "del", &h.ns]).output();
        }
        let _ = Command::new("ip")
            .args(["netns", "del", &self.switch])
            .output();
    }
}
