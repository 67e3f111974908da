//! The accept loop: axum's `serve`, plus a deadline for a client's request
//! headers (a client that trickles them in, or never sends them, is cut
//! off instead of holding a connection forever), TLS on the listeners that
//! have a certificate ([`tls`]), and graceful shutdown that lets requests
//! in flight finish.

pub mod tls;

use std::{sync::Arc, time::Duration};

use axum::Router;
use hyper::server::conn::http1::Builder;
use hyper_util::{
    rt::{TokioIo, TokioTimer},
    server::graceful::{GracefulShutdown, Watcher},
    service::TowerToHyperService,
};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::{TcpListener, TcpStream};
use tokio_rustls::{TlsAcceptor, rustls::ServerConfig};

/// A socket the API is served on, and whether it speaks TLS.
#[derive(Debug)]
pub struct Listener {
    /// The bound socket.
    pub tcp: TcpListener,
    /// Its TLS ([`tls::Certificate::config`]), or `None` for plain HTTP.
    pub tls: Option<Arc<ServerConfig>>,
}

/// Serves `app` on every listener until `shutdown` resolves, then waits
/// for the connections' requests in flight.
pub async fn serve(
    listeners: Vec<Listener>,
    app: Router,
    header_timeout: Duration,
    shutdown: impl Future<Output = ()>,
) -> std::io::Result<()> {
    // HTTP/1.1 alone: its header deadline runs from the moment a request
    // is awaited, so a connection that never sends a byte is cut off
    // too (hyper-util's auto builder first waits, with no deadline, for
    // the bytes that tell HTTP/2 apart).
    let mut builder = Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(header_timeout);
    let graceful = GracefulShutdown::new();
    // One task accepts on each socket; this loop starts the connections,
    // in the order they were accepted.
    let (accepted_tx, mut accepted) = tokio::sync::mpsc::channel(64);
    let acceptors: Vec<_> = listeners
        .into_iter()
        .map(|listener| tokio::spawn(accept(listener, accepted_tx.clone())))
        .collect();
    drop(accepted_tx);
    let mut shutdown = std::pin::pin!(shutdown);
    loop {
        let (stream, tls): (TcpStream, Option<Arc<ServerConfig>>) = tokio::select! {
            next = accepted.recv() => match next {
                Some(next) => next,
                None => break,
            },
            () = &mut shutdown => break,
        };
        // Taken before a handshake: shutdown waits for it (no longer
        // than the header deadline), and a connection whose handshake
        // ends after shutdown began is closed without a request.
        let watcher = graceful.watcher();
        let (builder, app) = (builder.clone(), app.clone());
        tokio::spawn(async move {
            match tls {
                None => serve_connection(&builder, watcher, stream, app).await,
                Some(tls) => {
                    // The handshake has a deadline of the same length: a
                    // client that never finishes it is cut off too.
                    let handshake = TlsAcceptor::from(tls).accept(stream);
                    if let Ok(Ok(stream)) = tokio::time::timeout(header_timeout, handshake).await {
                        serve_connection(&builder, watcher, stream, app).await;
                    }
                }
            }
        });
    }
    // The sockets close: new connections are refused from here on, and
    // those accepted but not yet started are closed.
    for acceptor in acceptors {
        acceptor.abort();
    }
    drop(accepted);
    graceful.shutdown().await;
    Ok(())
}

/// Accepts connections on `listener` and hands them on, until the
/// receiving end goes.
async fn accept(
    listener: Listener,
    accepted: tokio::sync::mpsc::Sender<(TcpStream, Option<Arc<ServerConfig>>)>,
) {
    loop {
        match listener.tcp.accept().await {
            Ok((stream, _peer)) => {
                let _ = stream.set_nodelay(true);
                if accepted.send((stream, listener.tls.clone())).await.is_err() {
                    return;
                }
            }
            // Out of file descriptors and the like: wait, go on.
            Err(e) => {
                log_line!("error: accept: {e}");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
}

/// Serves HTTP/1 on one connection (plain or TLS) until it closes or,
/// once shutdown begins, its request in flight is answered.
async fn serve_connection<I>(builder: &Builder, watcher: Watcher, io: I, app: Router)
where
    I: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let service = TowerToHyperService::new(app);
    let conn = builder.serve_connection(TokioIo::new(io), service);
    let _ = watcher.watch(conn).await;
}
