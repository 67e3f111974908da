//! `aobake blobs verify`: an operator's check of the blob store against
//! what the database names (`crate::repair`).

/// `aobake blobs`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Read every blob the database names (uploads, bakes' assets,
    /// reports and plots, jobs' outputs and checkpoints) and check that
    /// it is there and still hashes to its name; list each one that is
    /// missing or corrupt, who names it and what it means. With --repair:
    /// delete corrupt blobs, queue done bakes that lost what they serve
    /// again (they bake the same bytes), and forget lost checkpoints.
    /// Exits 1 while something is left for an operator (a lost upload:
    /// submit the file again; without --repair, what it would repair).
    Verify(VerifyArgs),
}

/// `aobake blobs verify`: the same stores `aobake serve` is given.
#[derive(Debug, clap::Args)]
pub(super) struct VerifyArgs {
    #[command(flatten)]
    backing: crate::serve::Backing,
    /// Repair what can be: delete corrupt blobs, queue done bakes that
    /// lost their asset, report, plot or previews again, forget lost
    /// checkpoints.
    #[arg(long)]
    repair: bool,
    /// Print the findings as JSON.
    #[arg(long)]
    json: bool,
}

/// Runs `aobake blobs`.
pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let Command::Verify(a) = &args.command;
    let verified = tokio::runtime::Runtime::new()?.block_on(async {
        let (store, blobs) = a.backing.open().await?;
        anyhow::Ok(crate::repair::verify(&*store, &*blobs, a.repair).await?)
    })?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&verified)?);
    } else {
        for f in &verified.findings {
            println!("{:<8} {}  {}: {}", f.damage, f.digest, f.named_by, f.action);
        }
        for (bake, why) in &verified.skipped {
            println!("skipped  bake {bake}: not queued again: {why}");
        }
        // A blob several name (an output that is also the asset) is one.
        let damaged: std::collections::BTreeSet<&str> = verified
            .findings
            .iter()
            .map(|f| f.digest.as_str())
            .collect();
        println!(
            "{} blobs read ({:.1} MB), {} damaged{}{}",
            verified.blobs,
            verified.bytes as f64 / 1e6,
            damaged.len(),
            match verified.findings.len() {
                n if n > damaged.len() => format!(" (named {n} times)"),
                _ => String::new(),
            },
            match verified.requeued.as_slice() {
                [] => String::new(),
                ids => format!(
                    "; bakes queued again: {}",
                    ids.iter()
                        .map(i64::to_string)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }
        );
    }
    let open: std::collections::BTreeSet<&str> = verified
        .findings
        .iter()
        .filter(|f| f.open)
        .map(|f| f.digest.as_str())
        .collect();
    let (open, skipped) = (open.len(), verified.skipped.len());
    if open + skipped > 0 {
        return Err(super::client::Exit {
            code: super::exit::FAILED,
            message: format!(
                "error: {open} damaged blob(s) and {skipped} bake(s) need more than this run did ({})",
                if a.repair {
                    "lost uploads: submit their files again"
                } else {
                    "--repair deletes what is corrupt and queues done bakes again; lost uploads: submit their files again"
                }
            ),
        }
        .into());
    }
    Ok(())
}
