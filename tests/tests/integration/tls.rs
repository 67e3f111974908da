//! `https://` servers: the command line and workers reach a server behind
//! TLS (a proxy that holds the certificate in front of `aobake serve`, or
//! `aobake serve --tls-cert` itself), trusting a private CA the way the
//! machine does, and refuse, saying why, a certificate they do not trust;
//! the server reads a renewed certificate on SIGHUP.

use std::{
    path::Path,
    sync::Arc,
    time::{Duration, Instant},
};

use aobake_e2e::{Options, TestEnv, character};

/// A CA of its own, its certificate's PEM written to `file`: its
/// parameters and key, to sign with.
fn certificate_authority(file: &Path) -> rcgen::Issuer<'static, rcgen::KeyPair> {
    use rcgen::{BasicConstraints, CertificateParams, IsCa, Issuer, KeyPair};
    let key = KeyPair::generate().unwrap();
    let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
    params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    std::fs::write(file, params.self_signed(&key).unwrap().pem()).unwrap();
    Issuer::new(params, key)
}

/// A new certificate for `localhost` that `issuer` signed, and its key.
fn localhost_certificate(
    issuer: &rcgen::Issuer<'static, rcgen::KeyPair>,
) -> (rcgen::Certificate, rcgen::KeyPair) {
    let key = rcgen::KeyPair::generate().unwrap();
    let cert = rcgen::CertificateParams::new(vec!["localhost".to_owned()])
        .unwrap()
        .signed_by(&key, issuer)
        .unwrap();
    (cert, key)
}

/// A TLS front on `localhost` for the server at `backend` (`host:port`),
/// its certificate from a CA of its own whose PEM it writes to
/// `ca_file`; its `https://` URL. It runs as long as the test.
fn tls_front(backend: &str, ca_file: &Path) -> String {
    let (cert, key) = localhost_certificate(&certificate_authority(ca_file));
    let config = tokio_rustls::rustls::ServerConfig::builder_with_provider(Arc::new(
        tokio_rustls::rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .unwrap()
    .with_no_client_auth()
    .with_single_cert(
        vec![cert.der().clone()],
        tokio_rustls::rustls::pki_types::PrivateKeyDer::Pkcs8(key.serialize_der().into()),
    )
    .unwrap();
    let acceptor = tokio_rustls::TlsAcceptor::from(Arc::new(config));
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    listener.set_nonblocking(true).unwrap();
    let backend = backend.to_owned();
    std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        runtime.block_on(async move {
            let listener = tokio::net::TcpListener::from_std(listener).unwrap();
            loop {
                let Ok((tcp, _)) = listener.accept().await else {
                    continue;
                };
                let (acceptor, backend) = (acceptor.clone(), backend.clone());
                tokio::spawn(async move {
                    // A handshake the client gives up on ends here.
                    let Ok(mut tls) = acceptor.accept(tcp).await else {
                        return;
                    };
                    if let Ok(mut plain) = tokio::net::TcpStream::connect(&backend).await {
                        let _ = tokio::io::copy_bidirectional(&mut tls, &mut plain).await;
                    }
                });
            }
        });
    });
    format!("https://localhost:{port}")
}

/// `aobake submit --wait --json` of a small bake to `url`, trusting the
/// CA in `ca` alone: it ends done.
fn a_small_bake_ends_done(env: &TestEnv, url: &str, ca: &Path) {
    let character = character("RiggedSimple");
    let out = env
        .aobake_command(&[
            "submit",
            character.to_str().unwrap(),
            "--method",
            "static-average",
            "--poses",
            "8",
            "--samples",
            "16",
            "--eval-poses",
            "2",
            "--wait",
            "--json",
        ])
        .env("AOBAKE_SERVER", url)
        .env("SSL_CERT_FILE", ca)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}\n{}\n{}",
        String::from_utf8_lossy(&out.stderr),
        env.server_log(),
        env.worker_logs()
    );
    let bake: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(bake["state"], "done", "{bake}");
}

#[test]
fn clients_and_workers_reach_an_https_server_that_the_machine_trusts() {
    let mut env = TestEnv::start(Options::default());
    let ca = env.dir.path().join("studio-ca.pem");
    let url = tls_front(env.url.trim_start_matches("http://"), &ca);
    let trusted = [("SSL_CERT_FILE", ca.to_str().unwrap())];
    // A worker and a submit over https, the CA trusted as the system's
    // own (SSL_CERT_FILE stands in for the trust store): the bake ends.
    env.start_worker_at(&url, &trusted);
    a_small_bake_ends_done(&env, &url, &ca);

    // A machine that trusts another CA refuses the certificate in the
    // handshake at once, not waited on as an outage: exit 1, saying what
    // to do.
    let other = env.dir.path().join("other-ca.pem");
    certificate_authority(&other);
    let started = std::time::Instant::now();
    let out = env
        .aobake_command(&["workers"])
        .env("AOBAKE_SERVER", &url)
        .env("SSL_CERT_FILE", &other)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{said}");
    assert!(
        said.contains("invalid peer certificate")
            && said.contains("not one this machine trusts")
            && said.contains("SSL_CERT_FILE"),
        "{said}"
    );
    assert!(started.elapsed() < Duration::from_secs(20), "{said}");
    // A plain http:// address of the TLS port: no HTTP answer comes
    // back, and the error says what the address likely is.
    let plain = url.replace("https://", "http://");
    let out = env
        .aobake_command(&["workers"])
        .env("AOBAKE_SERVER", &plain)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(7), "{said}");
    assert!(
        said.contains(&format!("if the server speaks https, its address is {url}")),
        "{said}"
    );
    // A worker that does not trust it exits 3, saying the same.
    let (exit, stderr) = crate::util::worker_until_it_exits(
        &url,
        &env.token(&["worker"]),
        &[("SSL_CERT_FILE", other.as_os_str())],
    );
    assert_eq!(exit.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("cannot talk to") && stderr.contains("not one this machine trusts"),
        "{stderr}"
    );
}

/// Writes a new `localhost` certificate from `issuer` and its key to
/// `cert` and `key` (PEM).
fn write_localhost_certificate(
    issuer: &rcgen::Issuer<'static, rcgen::KeyPair>,
    cert: &Path,
    key: &Path,
) {
    let (made, made_key) = localhost_certificate(issuer);
    std::fs::write(cert, made.pem()).unwrap();
    std::fs::write(key, made_key.serialize_pem()).unwrap();
}

/// `aobake workers` against `url`, trusting only the CA in `ca`.
fn workers_trusting(env: &TestEnv, url: &str, ca: &Path) -> std::process::Output {
    env.aobake_command(&["workers"])
        .env("AOBAKE_SERVER", url)
        .env("SSL_CERT_FILE", ca)
        .output()
        .unwrap()
}

#[test]
fn serve_speaks_https_itself_and_reads_a_renewed_certificate_on_sighup() {
    let files = tempfile::tempdir().unwrap();
    let path = |name: &str| files.path().join(name);
    let (cert, key) = (path("cert.pem"), path("key.pem"));
    write_localhost_certificate(&certificate_authority(&path("ca.pem")), &cert, &key);
    let env = TestEnv::start(Options {
        tls: Some((cert.clone(), key.clone())),
        local_workers: 1,
        header_timeout_secs: 2.0,
        ..Options::default()
    });
    // https on the port asked for (the certificate names localhost); a
    // plain listener of its own on the loopback in server.url, for the
    // local worker and this machine's commands.
    let https = env.public_url().replace("127.0.0.1", "localhost");
    assert!(https.starts_with("https://localhost:"), "{https}");
    assert!(env.url.starts_with("http://127.0.0.1:"), "{}", env.url);
    assert_ne!(
        env.url.rsplit(':').next(),
        https.rsplit(':').next(),
        "two listeners"
    );

    // A submit over https, trusting the CA; the local worker bakes it
    // over the loopback.
    a_small_bake_ends_done(&env, &https, &path("ca.pem"));

    // A client that opens the TLS port and never says hello is cut off at
    // the deadline (2 s), as a plain one is; so is one that says hello
    // and then no request.
    let port = https.rsplit(':').next().unwrap().parse::<u16>().unwrap();
    let connect = || {
        let tcp = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
        tcp.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        tcp
    };
    // The server closes it at the deadline, before the read times out:
    // what the read got.
    let cut_off = |mut stream: Box<dyn std::io::Read>| {
        let started = Instant::now();
        let read = stream.read(&mut [0u8; 64]);
        let waited = started.elapsed();
        assert!(
            waited > Duration::from_millis(1500) && waited < Duration::from_secs(15),
            "{waited:?}"
        );
        read
    };
    // Before hello: the connection ends, or is reset.
    let read = cut_off(Box::new(connect()));
    assert!(
        matches!(read, Ok(0))
            || read
                .as_ref()
                .is_err_and(|e| e.kind() == std::io::ErrorKind::ConnectionReset),
        "{read:?}"
    );
    {
        use tokio_rustls::rustls;
        let mut roots = rustls::RootCertStore::empty();
        let ca = std::fs::read(path("ca.pem")).unwrap();
        let ca = rustls::pki_types::pem::PemObject::from_pem_slice(&ca).unwrap();
        roots.add(ca).unwrap();
        let config = rustls::ClientConfig::builder_with_provider(Arc::new(
            rustls::crypto::ring::default_provider(),
        ))
        .with_safe_default_protocol_versions()
        .unwrap()
        .with_root_certificates(roots)
        .with_no_client_auth();
        let name = rustls::pki_types::ServerName::try_from("localhost").unwrap();
        let conn = rustls::ClientConnection::new(Arc::new(config), name).unwrap();
        let mut tls = rustls::StreamOwned::new(conn, connect());
        while tls.conn.is_handshaking() {
            tls.conn.complete_io(&mut tls.sock).unwrap();
        }
        // Closed, with or without close_notify (or a 408 first).
        let read = cut_off(Box::new(tls));
        assert!(
            read.is_ok()
                || read
                    .as_ref()
                    .is_err_and(|e| e.kind() == std::io::ErrorKind::UnexpectedEof),
            "{read:?}"
        );
    }

    // Renewal: a certificate from another CA in the same files, then
    // SIGHUP. New handshakes present it: a machine that trusts only the
    // new CA gets in, one that trusts only the old one is refused.
    write_localhost_certificate(&certificate_authority(&path("ca2.pem")), &cert, &key);
    // SIGHUP, then the log's line that says what came of it.
    let hangup_until_it_says = |line: &str| {
        let pid = nix::unistd::Pid::from_raw(env.server_pid().unwrap() as i32);
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGHUP).unwrap();
        let started = Instant::now();
        while !env.server_log().contains(line) {
            assert!(
                started.elapsed() < Duration::from_secs(20),
                "{}",
                env.server_log()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    hangup_until_it_says("reloaded the TLS certificate");
    let out = workers_trusting(&env, &https, &path("ca2.pem"));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = workers_trusting(&env, &https, &path("ca.pem"));
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{said}");
    assert!(said.contains("not one this machine trusts"), "{said}");

    // A renewal that does not load is logged, and the certificate served
    // stays.
    std::fs::write(&key, "not a key").unwrap();
    hangup_until_it_says("was not reloaded");
    assert!(
        env.server_log().contains("key.pem holds no private key"),
        "{}",
        env.server_log()
    );
    let out = workers_trusting(&env, &https, &path("ca2.pem"));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn serve_refuses_tls_files_that_cannot_serve_before_it_starts() {
    let files = tempfile::tempdir().unwrap();
    let path = |name: &str| files.path().join(name);
    let issuer = certificate_authority(&path("ca.pem"));
    write_localhost_certificate(&issuer, &path("cert.pem"), &path("key.pem"));
    write_localhost_certificate(&issuer, &path("other.pem"), &path("other.key"));
    let serve = |tls: &[&str]| {
        let mut command = std::process::Command::new(aobake_e2e::binary());
        command
            .args([
                "serve",
                "--listen",
                "127.0.0.1:0",
                "--workers",
                "0",
                "--data",
            ])
            .arg(path("data"));
        for arg in tls {
            command.arg(if arg.starts_with("--") {
                arg.into()
            } else {
                path(arg)
            });
        }
        let out = command.output().unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    // Another certificate's key: the server does not start, and says so
    // before it makes its data folder.
    let (code, said) = serve(&["--tls-cert", "cert.pem", "--tls-key", "other.key"]);
    assert_eq!(code, Some(1), "{said}");
    assert!(
        said.contains("other.key is not the key of the first certificate in")
            && said.contains("cert.pem"),
        "{said}"
    );
    assert!(!path("data").exists());
    // A file that is not there is named.
    let (code, said) = serve(&["--tls-cert", "gone.pem", "--tls-key", "key.pem"]);
    assert_eq!(code, Some(1), "{said}");
    assert!(
        said.contains("cannot read the TLS certificate") && said.contains("gone.pem"),
        "{said}"
    );
    // One without the other is a wrong command line.
    let (code, said) = serve(&["--tls-cert", "cert.pem"]);
    assert_eq!(code, Some(2), "{said}");
    assert!(said.contains("--tls-key"), "{said}");
}
