//! The embedded store: SQLite in WAL mode through sqlx. Only what SQLite
//! does differently from the shared queue (`queue.rs`) lives here.
//!
//! SQLite has one writer at a time, so writes take turns on one connection
//! (a queue instead of busy-waiting) in `BEGIN IMMEDIATE` transactions that
//! take the write lock up front, and reads go through a read-only pool.
//! Acknowledged writes commit with `synchronous = FULL`, queue writes with
//! `NORMAL`; a busy timeout waits out writers in other processes.

use std::ops::{Deref, DerefMut};
use std::str::FromStr as _;
use std::sync::Arc;
use std::time::Duration;

use sqlx::pool::PoolConnection;
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteConnection, SqliteJournalMode, SqlitePool, SqlitePoolOptions,
    SqliteSynchronous,
};
use tokio::sync::{Mutex, OwnedMutexGuard};

use super::Result;
use super::queue::{Backend, Durability, SqlStore, sql_conn};

sql_conn!(SqliteConnection, sqlx::Sqlite);

/// SQLite behind the [`Store`](super::Store) trait.
pub type SqliteStore = SqlStore<Sqlite>;

/// The SQLite engine: a read pool, one writer and its turn.
#[derive(Debug, Clone)]
pub struct Sqlite {
    pool: SqlitePool,
    writer: SqlitePool,
    write_turn: Arc<Mutex<()>>,
}

/// A write transaction holding the writer's turn until it ends.
pub(super) struct SqliteTx {
    tx: sqlx::Transaction<'static, sqlx::Sqlite>,
    _turn: OwnedMutexGuard<()>,
}

impl Deref for SqliteTx {
    type Target = SqliteConnection;
    fn deref(&self) -> &SqliteConnection {
        &self.tx
    }
}

impl DerefMut for SqliteTx {
    fn deref_mut(&mut self) -> &mut SqliteConnection {
        &mut self.tx
    }
}

impl SqliteStore {
    /// Opens (creating if needed) the database at `path` and migrates it.
    pub async fn open(path: &std::path::Path) -> Result<Self> {
        let options = SqliteConnectOptions::from_str("sqlite://")?
            .filename(path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Full)
            .busy_timeout(Duration::from_secs(10))
            .foreign_keys(true);
        let writer = SqlitePoolOptions::new()
            .max_connections(1)
            .connect_with(options.clone())
            .await?;
        sqlx::migrate!("migrations/sqlite").run(&writer).await?;
        let pool = SqlitePoolOptions::new()
            .max_connections(8)
            .connect_with(options.read_only(true))
            .await?;
        Ok(Self {
            backend: Sqlite {
                pool,
                writer,
                write_turn: Default::default(),
            },
        })
    }
}

#[async_trait::async_trait]
impl Backend for Sqlite {
    type Conn = SqliteConnection;
    type Tx = SqliteTx;
    type Read = PoolConnection<sqlx::Sqlite>;

    const NOW: &'static str = "CAST(unixepoch('subsec') * 1000 AS INTEGER)";
    const DEPS: &'static str = "(SELECT group_concat(d.dep_idx) FROM (SELECT dep_idx FROM job_deps WHERE job_id = jobs.id ORDER BY dep_idx) d)";
    // One writer at a time: a transaction's reads are already its own.
    const FOR_UPDATE: &'static str = "";
    const SKIP_LOCKED: &'static str = "";

    async fn begin(&self, durability: Durability) -> Result<SqliteTx> {
        let turn = self.write_turn.clone().lock_owned().await;
        let pragma = match durability {
            Durability::Acknowledged => "PRAGMA synchronous = FULL",
            Durability::Queue => "PRAGMA synchronous = NORMAL",
        };
        sqlx::query(pragma).execute(&self.writer).await?;
        let tx = self.writer.begin_with("BEGIN IMMEDIATE").await?;
        Ok(SqliteTx { tx, _turn: turn })
    }

    async fn commit(tx: SqliteTx) -> Result<()> {
        tx.tx.commit().await?;
        Ok(())
    }

    async fn rollback(tx: SqliteTx) {
        let _ = tx.tx.rollback().await;
    }

    async fn read(&self) -> Result<Self::Read> {
        Ok(self.pool.acquire().await?)
    }
}

#[cfg(test)]
mod tests {
    #[tokio::test]
    async fn the_shared_store_suite_passes_on_sqlite() {
        let dir = tempfile::tempdir().unwrap();
        let store = super::SqliteStore::open(&dir.path().join("t.db"))
            .await
            .unwrap();
        super::super::suite::run_all(&store).await;
    }
}
