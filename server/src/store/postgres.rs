//! The scale-out store: PostgreSQL through sqlx, for several servers and
//! many workers. Only what PostgreSQL does differently from the shared
//! queue (`queue.rs`) lives here: claims lock the chosen row with `FOR
//! UPDATE SKIP LOCKED` (concurrent claimers skip each other's rows instead
//! of waiting), and `NOTIFY aobake_jobs` goes out whenever jobs may have
//! become ready, which every server `LISTEN`s to so its long-polling
//! workers wake wherever the change was made. Queue writes commit with
//! `synchronous_commit = off`; what a client is told is done waits for
//! the WAL flush.

use std::sync::Arc;

use sqlx::pool::PoolConnection;
use sqlx::postgres::{PgConnection, PgListener, PgPool, PgPoolOptions};

use super::Result;
use super::queue::{Backend, Durability, SqlStore, sql_conn};
use crate::state::BakeEvent;

sql_conn!(PgConnection, sqlx::Postgres);

/// PostgreSQL behind the [`Store`](super::Store) trait.
pub type PgStore = SqlStore<Postgres>;

/// The PostgreSQL engine: a pool.
#[derive(Debug, Clone)]
pub struct Postgres {
    pool: PgPool,
    /// Its outages, for the log.
    outages: super::Outages,
}

impl PgStore {
    /// Connects to `url` (`postgres://user@host:port/db`) and migrates.
    pub async fn connect(url: &str) -> Result<Self> {
        let pool = PgPoolOptions::new()
            .max_connections(16)
            // While the database is down a request waits this long for a
            // connection, then gets a 503 with Retry-After.
            .acquire_timeout(std::time::Duration::from_secs(3))
            .connect(url)
            .await;
        let pool = match pool {
            Ok(pool) => pool,
            // The pool says only that it timed out: one connection says
            // why (refused, no such database, a password refused).
            Err(sqlx::Error::PoolTimedOut) => {
                use sqlx::Connection as _;
                let once = std::time::Duration::from_secs(10);
                return Err(
                    match tokio::time::timeout(once, sqlx::PgConnection::connect(url)).await {
                        Ok(Err(why)) => why.into(),
                        Ok(Ok(_)) | Err(_) => sqlx::Error::PoolTimedOut.into(),
                    },
                );
            }
            Err(e) => return Err(e.into()),
        };
        sqlx::migrate!("migrations/postgres").run(&pool).await?;
        Ok(Self {
            backend: Postgres {
                pool,
                outages: super::Outages::default(),
            },
        })
    }
}

#[async_trait::async_trait]
impl Backend for Postgres {
    type Conn = PgConnection;
    type Tx = sqlx::Transaction<'static, sqlx::Postgres>;
    type Read = PoolConnection<sqlx::Postgres>;

    const NOW: &'static str = "(extract(epoch FROM clock_timestamp()) * 1000)::bigint";
    const DEPS: &'static str = "(SELECT string_agg(d.dep_idx::text, ',' ORDER BY d.dep_idx) FROM job_deps d WHERE d.job_id = jobs.id)";
    const FOR_UPDATE: &'static str = " FOR UPDATE";
    const SKIP_LOCKED: &'static str = " FOR UPDATE SKIP LOCKED";

    async fn begin(&self, durability: Durability) -> Result<Self::Tx> {
        let asked = std::time::Instant::now();
        let mut tx = self.outages.heard(asked, self.pool.begin().await)?;
        if durability == Durability::Queue {
            sqlx::query("SET LOCAL synchronous_commit TO OFF")
                .execute(&mut *tx)
                .await?;
        }
        Ok(tx)
    }

    async fn commit(tx: Self::Tx) -> Result<()> {
        tx.commit().await?;
        Ok(())
    }

    async fn rollback(tx: Self::Tx) {
        let _ = tx.rollback().await;
    }

    async fn read(&self) -> Result<Self::Read> {
        let asked = std::time::Instant::now();
        Ok(self.outages.heard(asked, self.pool.acquire().await)?)
    }

    async fn wake(tx: &mut PgConnection) -> Result<()> {
        sqlx::query("SELECT pg_notify('aobake_jobs', '')")
            .execute(tx)
            .await?;
        Ok(())
    }

    async fn listen(&self, ready: Arc<tokio::sync::Notify>) -> Result<()> {
        listen_on(&self.pool, "aobake_jobs", move |_| ready.notify_waiters()).await
    }

    async fn share_events(
        &self,
        events: tokio::sync::broadcast::Sender<BakeEvent>,
    ) -> Result<Option<tokio::sync::mpsc::UnboundedSender<BakeEvent>>> {
        let heard = events.clone();
        listen_on(
            &self.pool,
            BAKE_EVENTS,
            move |payload| match serde_json::from_str(payload) {
                Ok(event) => {
                    let _ = heard.send(event);
                }
                Err(e) => log_line!("error: a bake event that does not parse: {e}"),
            },
        )
        .await?;
        // One task sends this server's events, in order; one the database
        // cannot take still reaches this server's listeners.
        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<BakeEvent>();
        let pool = self.pool.clone();
        tokio::spawn(async move {
            while let Some(event) = rx.recv().await {
                let payload = serde_json::to_string(&event).expect("events serialise");
                let sent = sqlx::query("SELECT pg_notify($1, $2)")
                    .bind(BAKE_EVENTS)
                    .bind(payload)
                    .execute(&pool)
                    .await;
                if let Err(e) = sent {
                    log_line!("error: NOTIFY {BAKE_EVENTS}: {e}");
                    let _ = events.send(event);
                }
            }
        });
        Ok(Some(tx))
    }
}

/// Listens on `channel` on a connection of its own and calls `heard`
/// with each payload, for as long as the server runs (the listener
/// reconnects after an error, which is logged).
async fn listen_on(
    pool: &sqlx::PgPool,
    channel: &'static str,
    heard: impl Fn(&str) + Send + 'static,
) -> Result<()> {
    let mut listener = PgListener::connect_with(pool).await?;
    listener.listen(channel).await?;
    tokio::spawn(async move {
        loop {
            match listener.recv().await {
                Ok(n) => heard(n.payload()),
                Err(e) => {
                    log_line!("error: LISTEN {channel}: {e}");
                    tokio::time::sleep(std::time::Duration::from_secs(1)).await;
                }
            }
        }
    });
    Ok(())
}

/// The channel bake events travel on between servers (JSON payloads).
const BAKE_EVENTS: &str = "aobake_bakes";

#[cfg(test)]
mod tests {
    #[tokio::test]
    async fn the_shared_store_suite_passes_on_postgres() {
        let pg = aobake_e2e::TestPostgres::start();
        let store = super::PgStore::connect(&pg.url).await.unwrap();
        super::super::suite::run_all(&store).await;
        // Claims made at once by many connections never hand out one job
        // twice (FOR UPDATE SKIP LOCKED).
        super::super::suite::concurrent_claims_are_exclusive(std::sync::Arc::new(store)).await;
        // Two servers on the database: each hears the other's bake events.
        let a = super::PgStore::connect(&pg.url).await.unwrap();
        let b = super::PgStore::connect(&pg.url).await.unwrap();
        super::super::suite::bake_events_reach_every_server(
            std::sync::Arc::new(a),
            std::sync::Arc::new(b),
        )
        .await;
    }
}
