//! `https://` servers: the command line and workers reach a server behind
//! TLS (the way a studio runs one: a proxy that holds the certificate in
//! front of `aobake serve`), trusting a private CA the way the machine
//! does, and refuse, saying why, a certificate they do not trust.

use std::{path::Path, sync::Arc, time::Duration};

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

/// A TLS front on `localhost` for the server at `backend` (`host:port`),
/// its certificate from a CA of its own whose PEM it writes to
/// `ca_file`; its `https://` URL. It runs as long as the test.
fn tls_front(backend: &str, ca_file: &Path) -> String {
    use rcgen::{CertificateParams, KeyPair};
    let issuer = certificate_authority(ca_file);
    let key = KeyPair::generate().unwrap();
    let cert = CertificateParams::new(vec!["localhost".to_owned()])
        .unwrap()
        .signed_by(&key, &issuer)
        .unwrap();
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

#[test]
fn clients_and_workers_reach_an_https_server_that_the_machine_trusts() {
    let mut env = TestEnv::start(Options::default());
    let ca = env.dir.path().join("studio-ca.pem");
    let url = tls_front(env.url.trim_start_matches("http://"), &ca);
    let trusted = [("SSL_CERT_FILE", ca.to_str().unwrap())];
    // A worker and a submit over https, the CA trusted as the system's
    // own (SSL_CERT_FILE stands in for the trust store): the bake ends.
    env.start_worker_at(&url, &trusted);
    let cm = character("RiggedSimple");
    let out = env
        .aobake_command(&[
            "submit",
            cm.to_str().unwrap(),
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
        .env("AOBAKE_SERVER", &url)
        .env("SSL_CERT_FILE", &ca)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stderr),
        env.worker_logs()
    );
    let bake: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(bake["state"], "done", "{bake}");

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
