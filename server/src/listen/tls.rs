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

    /// The certificate served now.
    fn current(&self) -> Arc<CertifiedKey> {
        self.current
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// The host names and addresses the certificate served is for (its
    /// subjectAltName; clients read no other), as clients compare them.
    pub fn names(&self) -> Vec<String> {
        let current = self.current();
        end_entity(&current).map_or_else(Vec::new, |cert| names(&cert))
    }

    /// Why a client refuses the certificate served, whoever its CA is,
    /// if one does: expired or not yet valid, a CA's certificate served
    /// as a server's, one not for servers, or one that names no host. The
    /// server still presents it (a browser told to may take it); the log
    /// says so at once, instead of each client failing its handshake.
    pub fn refused_by_clients(&self) -> Option<String> {
        let current = self.current();
        let cert = end_entity(&current)?;
        let path = self.files.cert.display();
        if names(&cert).is_empty() {
            return Some(format!(
                "{path} names no host: clients look for the server's name in its subjectAltName extension, which it lacks (a CN alone is not read); make one that has it, e.g. {SELF_SIGNED}"
            ));
        }
        // No trust anchor: what fails first is what a client checks of
        // the certificate alone (dates, basic constraints, key usage),
        // else the unknown issuer, which is the client's to know.
        let checked = cert.verify_for_usage(
            provider().signature_verification_algorithms.all,
            &[],
            &current.cert[1..],
            rustls::pki_types::UnixTime::now(),
            webpki::KeyUsage::server_auth(),
            None,
            None,
        );
        match checked.err()? {
            webpki::Error::CertExpired { .. } => Some(format!("{path} has expired")),
            webpki::Error::CertNotValidYet { .. } => Some(format!("{path} is not valid yet")),
            webpki::Error::CaUsedAsEndEntity => Some(format!(
                "{path} is a CA's certificate (basicConstraints CA:TRUE, which `openssl req -x509` writes unless told otherwise), and TLS clients such as aobake's refuse it as a server's own: serve a certificate that a CA signed, or a self-signed one that is not a CA's, e.g. {SELF_SIGNED}"
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
        let mut config = rustls::ServerConfig::builder_with_provider(Arc::new(provider()))
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
        Some(self.current())
    }
}

/// The certificate's end-entity certificate, parsed.
fn end_entity(key: &CertifiedKey) -> Option<webpki::EndEntityCert<'_>> {
    webpki::EndEntityCert::try_from(key.end_entity_cert().ok()?).ok()
}

/// The host names and addresses `cert`'s subjectAltName holds.
fn names(cert: &webpki::EndEntityCert<'_>) -> Vec<String> {
    // Checked against a name no certificate holds, the refusal lists
    // the names it does hold.
    let nobody = rustls::pki_types::ServerName::try_from("aobake.invalid").expect("a name");
    let Err(webpki::Error::CertNotValidForName(context)) =
        cert.verify_is_valid_for_subject_name(&nobody)
    else {
        return Vec::new();
    };
    // webpki lists them in their Debug form, `DnsName("…")` and
    // `IpAddress(…)` (the unit test pins it); other kinds of name
    // (a URI, a directory name) are no host.
    context
        .presented
        .iter()
        .filter_map(|shown| {
            if let Some(dns) = shown
                .strip_prefix("DnsName(\"")
                .and_then(|r| r.strip_suffix("\")"))
            {
                return Some(dns.to_owned());
            }
            let ip = shown.strip_prefix("IpAddress(")?.strip_suffix(')')?;
            Some(
                ip.parse::<std::net::IpAddr>()
                    .map_or_else(|_| ip.to_owned(), |ip| ip.to_string()),
            )
        })
        .collect()
}

/// The crypto every TLS piece here uses: ring, as the rest of aobake.
fn provider() -> rustls::crypto::CryptoProvider {
    rustls::crypto::ring::default_provider()
}

/// A self-signed certificate that clients take (once they trust it), as
/// the warnings suggest it.
const SELF_SIGNED: &str = "`openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 365 -subj /CN=HOST -addext subjectAltName=DNS:HOST -addext basicConstraints=critical,CA:FALSE -keyout key.pem -out cert.pem` (HOST: the name clients use)";

/// The chain and key of `files`, checked to belong together.
fn read(files: &TlsFiles) -> anyhow::Result<CertifiedKey> {
    let cert_pem = read_file(&files.cert, "certificate")?;
    let chain = CertificateDer::pem_slice_iter(&cert_pem)
        .collect::<Result<Vec<_>, _>>()
        .with_context(|| format!("{} is not a PEM file", files.cert.display()))?;
    let key_pem = read_file(&files.key, "key")?;
    if chain.is_empty() {
        let swapped = PrivateKeyDer::from_pem_slice(&cert_pem).is_ok()
            && CertificateDer::pem_slice_iter(&key_pem).any(|c| c.is_ok());
        anyhow::bail!(
            "{} holds no certificate (a PEM \"BEGIN CERTIFICATE\" block){}",
            files.cert.display(),
            if swapped {
                ": it holds a key, and the key file a certificate; are --tls-cert and --tls-key swapped?"
            } else {
                ""
            }
        );
    }
    if is_encrypted(&key_pem) {
        anyhow::bail!(
            "{0} is encrypted, and a server that starts on its own has no passphrase to give: decrypt it into a file only the server's user reads (`openssl pkey -in {0} -out key.pem`)",
            files.key.display()
        );
    }
    let key = PrivateKeyDer::from_pem_slice(&key_pem).map_err(|e| match e {
        rustls::pki_types::pem::Error::NoItemsFound => anyhow::anyhow!(
            "{} holds no private key (an unencrypted PKCS#8, PKCS#1 or SEC1 PEM block)",
            files.key.display()
        ),
        e => anyhow::anyhow!("{} is not a PEM file: {e}", files.key.display()),
    })?;
    CertifiedKey::from_der(chain, key, &provider()).map_err(|e| match e {
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

/// Whether a PEM file holds an encrypted key: PKCS#8's `ENCRYPTED
/// PRIVATE KEY` block, or OpenSSL's traditional `Proc-Type: 4,ENCRYPTED`
/// header (whose body the PEM reader cannot even parse).
fn is_encrypted(pem: &[u8]) -> bool {
    let has = |needle: &[u8]| pem.windows(needle.len()).any(|w| w == needle);
    has(b"-----BEGIN ENCRYPTED PRIVATE KEY-----") || has(b"Proc-Type: 4,ENCRYPTED")
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
        assert!(!said.contains("swapped"), "{said}");
        let said = refused(files(dir.path(), &key, &cert));
        assert!(
            said.contains("are --tls-cert and --tls-key swapped?"),
            "{said}"
        );
        // Encrypted keys, both ways OpenSSL writes them.
        let pkcs8 = "-----BEGIN ENCRYPTED PRIVATE KEY-----\nMIIFHDBOBgkqhkiG9w0BBQ0wQTApBgkqhkiG9w0BBQwwHAQI\n-----END ENCRYPTED PRIVATE KEY-----\n";
        let traditional = "-----BEGIN RSA PRIVATE KEY-----\nProc-Type: 4,ENCRYPTED\nDEK-Info: AES-256-CBC,0123456789ABCDEF0123456789ABCDEF\n\nAAAA\n-----END RSA PRIVATE KEY-----\n";
        for encrypted in [pkcs8, traditional] {
            let said = refused(files(dir.path(), &cert, encrypted));
            assert!(
                said.contains("key.pem is encrypted") && said.contains("openssl pkey"),
                "{said}"
            );
        }
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
        let mut both = localhost();
        both.subject_alt_names
            .push(rcgen::SanType::IpAddress([127, 0, 0, 1].into()));
        both.subject_alt_names.push(rcgen::SanType::IpAddress(
            std::net::Ipv6Addr::LOCALHOST.into(),
        ));
        let key = KeyPair::generate().unwrap();
        let cert = both.self_signed(&key).unwrap().pem();
        let loaded = Certificate::load(files(dir.path(), &cert, &key.serialize_pem())).unwrap();
        assert_eq!(loaded.names(), ["localhost", "127.0.0.1", "::1"]);
        // A CN alone names nothing a client reads.
        let mut cn_only = CertificateParams::new(Vec::<String>::new()).unwrap();
        cn_only
            .distinguished_name
            .push(rcgen::DnType::CommonName, "localhost");
        assert!(
            said(cn_only).is_some_and(
                |s| s.contains("names no host") && s.contains("subjectAltName=DNS:HOST")
            )
        );
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
        let served = || loaded.current().cert[0].clone();
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
