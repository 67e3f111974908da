//! TLS for `aobake serve` (`--tls-cert`, `--tls-key`): the certificate
//! chain and its key, read from PEM files and checked against each other
//! at start, and read again on SIGHUP, so that a renewed certificate is
//! served without a restart (one that does not load leaves the previous
//! one in place).

use std::path::{Path, PathBuf};
use std::sync::{Arc, RwLock};

use anyhow::Context as _;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, pem::PemObject as _};
use rustls::server::{ClientHello, ResolvesServerCert};
use rustls::sign::CertifiedKey;

/// The files a server's certificate comes from.
#[derive(Debug, Clone)]
pub struct TlsFiles {
    /// PEM: the server's certificate first, then the chain to its CA.
    pub cert: PathBuf,
    /// PEM: its private key (PKCS#8, PKCS#1 or SEC1, not encrypted).
    pub key: PathBuf,
}

/// The certificate a server presents: the one last loaded.
#[derive(Debug)]
pub struct Certificate {
    files: TlsFiles,
    current: RwLock<Arc<CertifiedKey>>,
}

impl Certificate {
    /// Reads and checks `files`.
    pub fn load(files: TlsFiles) -> anyhow::Result<Arc<Self>> {
        let key = read(&files)?;
        Ok(Arc::new(Self {
            files,
            current: RwLock::new(Arc::new(key)),
        }))
    }

    /// The files it comes from.
    pub fn files(&self) -> &TlsFiles {
        &self.files
    }

    /// Why a client refuses the certificate served, whoever its CA is,
    /// if one does: expired or not yet valid, a CA's certificate served
    /// as a server's, or one not for servers. The server still presents
    /// it (a browser told to may take it); the log says so at once,
    /// instead of each client failing its handshake.
    pub fn refused_by_clients(&self) -> Option<String> {
        let current = self
            .current
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        let der = current.end_entity_cert().ok()?;
        let cert = webpki::EndEntityCert::try_from(der).ok()?;
        let provider = rustls::crypto::ring::default_provider();
        // No trust anchor: what fails first is what a client checks of
        // the certificate alone (dates, basic constraints, key usage),
        // else the unknown issuer, which is the client's to know.
        let checked = cert.verify_for_usage(
            provider.signature_verification_algorithms.all,
            &[],
            &current.cert[1..],
            rustls::pki_types::UnixTime::now(),
            webpki::KeyUsage::server_auth(),
            None,
            None,
        );
        let path = self.files.cert.display();
        match checked.err()? {
            webpki::Error::CertExpired { .. } => Some(format!("{path} has expired")),
            webpki::Error::CertNotValidYet { .. } => Some(format!("{path} is not valid yet")),
            webpki::Error::CaUsedAsEndEntity => Some(format!(
                "{path} is a CA's certificate (basicConstraints CA:TRUE, which `openssl req -x509` writes unless given `-addext basicConstraints=critical,CA:FALSE`), and TLS clients such as aobake's refuse it as a server's own: serve a certificate that a CA signed, or a self-signed one that is not a CA's"
            )),
            webpki::Error::RequiredEkuNotFoundContext(_) => Some(format!(
                "{path} is not a server's certificate (its extended key usage lacks serverAuth)"
            )),
            _ => None,
        }
    }

    /// Reads the files again; on success new handshakes present what they
    /// hold, else the certificate served so far stays.
    pub fn reload(&self) -> anyhow::Result<()> {
        let key = Arc::new(read(&self.files)?);
        *self.current.write().unwrap_or_else(|e| e.into_inner()) = key;
        Ok(())
    }

    /// A server's TLS that presents this certificate (as reloaded): TLS
    /// 1.2 and 1.3 on ring, HTTP/1.1.
    pub fn config(self: &Arc<Self>) -> anyhow::Result<Arc<rustls::ServerConfig>> {
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let mut config = rustls::ServerConfig::builder_with_provider(provider)
            .with_safe_default_protocol_versions()
            .context("TLS setup")?
            .with_no_client_auth()
            .with_cert_resolver(self.clone());
        config.alpn_protocols = vec![b"http/1.1".to_vec()];
        Ok(Arc::new(config))
    }
}

impl ResolvesServerCert for Certificate {
    fn resolve(&self, _: ClientHello<'_>) -> Option<Arc<CertifiedKey>> {
        Some(
            self.current
                .read()
                .unwrap_or_else(|e| e.into_inner())
                .clone(),
        )
    }
}

/// The chain and key of `files`, checked to belong together.
fn read(files: &TlsFiles) -> anyhow::Result<CertifiedKey> {
    let cert_pem = read_file(&files.cert, "certificate")?;
    let chain = CertificateDer::pem_slice_iter(&cert_pem)
        .collect::<Result<Vec<_>, _>>()
        .with_context(|| format!("{} is not a PEM file", files.cert.display()))?;
    anyhow::ensure!(
        !chain.is_empty(),
        "{} holds no certificate (a PEM \"BEGIN CERTIFICATE\" block)",
        files.cert.display()
    );
    let key_pem = read_file(&files.key, "key")?;
    let key = PrivateKeyDer::from_pem_slice(&key_pem).map_err(|e| match e {
        rustls::pki_types::pem::Error::NoItemsFound => anyhow::anyhow!(
            "{} holds no private key (an unencrypted PKCS#8, PKCS#1 or SEC1 PEM block)",
            files.key.display()
        ),
        e => anyhow::anyhow!("{} is not a PEM file: {e}", files.key.display()),
    })?;
    let provider = rustls::crypto::ring::default_provider();
    CertifiedKey::from_der(chain, key, &provider).map_err(|e| match e {
        rustls::Error::InconsistentKeys(_) => anyhow::anyhow!(
            "the key in {} is not the key of the first certificate in {} (the server's own certificate comes first, then its chain)",
            files.key.display(),
            files.cert.display()
        ),
        e => anyhow::anyhow!(
            "the TLS certificate {} and key {} cannot be used: {e}",
            files.cert.display(),
            files.key.display()
        ),
    })
}

fn read_file(path: &Path, what: &str) -> anyhow::Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("cannot read the TLS {what} {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A self-signed certificate for `localhost` and its key, as PEM.
    fn self_signed() -> (String, String) {
        let made = rcgen::generate_simple_self_signed(vec!["localhost".to_owned()]).unwrap();
        (made.cert.pem(), made.signing_key.serialize_pem())
    }

    fn files(dir: &Path, cert: &str, key: &str) -> TlsFiles {
        let files = TlsFiles {
            cert: dir.join("cert.pem"),
            key: dir.join("key.pem"),
        };
        std::fs::write(&files.cert, cert).unwrap();
        std::fs::write(&files.key, key).unwrap();
        files
    }

    fn refused(files: TlsFiles) -> String {
        format!("{:#}", Certificate::load(files).unwrap_err())
    }

    #[test]
    fn a_certificate_loads_with_its_own_key_and_no_other() {
        let dir = tempfile::tempdir().unwrap();
        let (cert, key) = self_signed();
        let (_, other_key) = self_signed();
        let loaded = Certificate::load(files(dir.path(), &cert, &key)).unwrap();
        loaded.config().unwrap();
        // One file may hold both.
        let both = format!("{cert}{key}");
        Certificate::load(files(dir.path(), &both, &both)).unwrap();

        let said = refused(files(dir.path(), &cert, &other_key));
        assert!(
            said.contains("is not the key of the first certificate"),
            "{said}"
        );
        let said = refused(files(dir.path(), &key, &key));
        assert!(said.contains("cert.pem holds no certificate"), "{said}");
        let said = refused(files(dir.path(), &cert, &cert));
        assert!(said.contains("key.pem holds no private key"), "{said}");
        let cut = &cert[..cert.len() - 30];
        let said = refused(files(dir.path(), cut, &key));
        assert!(said.contains("cert.pem is not a PEM file"), "{said}");
        let gone = TlsFiles {
            cert: dir.path().join("missing.pem"),
            key: dir.path().join("key.pem"),
        };
        let said = refused(gone);
        assert!(
            said.contains("cannot read the TLS certificate") && said.contains("missing.pem"),
            "{said}"
        );
    }

    #[test]
    fn a_certificate_clients_refuse_is_told_apart() {
        use rcgen::{BasicConstraints, CertificateParams, ExtendedKeyUsagePurpose, IsCa, KeyPair};
        let dir = tempfile::tempdir().unwrap();
        let said = |params: CertificateParams| {
            let key = KeyPair::generate().unwrap();
            let cert = params.self_signed(&key).unwrap().pem();
            Certificate::load(files(dir.path(), &cert, &key.serialize_pem()))
                .unwrap()
                .refused_by_clients()
        };
        let localhost = || CertificateParams::new(vec!["localhost".to_owned()]).unwrap();
        // A self-signed server certificate is fine (its client trusts it
        // or does not).
        assert_eq!(said(localhost()), None);
        let mut ca = localhost();
        ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        assert!(said(ca).is_some_and(|s| s.contains("is a CA's certificate")));
        let mut old = localhost();
        old.not_before = rcgen::date_time_ymd(2020, 1, 1);
        old.not_after = rcgen::date_time_ymd(2021, 1, 1);
        assert!(said(old).is_some_and(|s| s.contains("has expired")));
        let mut client = localhost();
        client.extended_key_usages = vec![ExtendedKeyUsagePurpose::ClientAuth];
        assert!(said(client).is_some_and(|s| s.contains("lacks serverAuth")));
    }

    #[test]
    fn a_reload_that_fails_keeps_the_certificate_served() {
        let dir = tempfile::tempdir().unwrap();
        let (cert, key) = self_signed();
        let loaded = Certificate::load(files(dir.path(), &cert, &key)).unwrap();
        let served = || loaded.current.read().unwrap().cert[0].clone();
        let first = served();
        std::fs::write(&loaded.files().key, "not a key").unwrap();
        assert!(loaded.reload().is_err());
        assert_eq!(served(), first);
        let (cert, key) = self_signed();
        files(dir.path(), &cert, &key);
        loaded.reload().unwrap();
        assert_ne!(served(), first);
    }
}
