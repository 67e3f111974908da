//! `aobake key`: the bake key of inputs and parameters, without baking:
//! what CI computes to fetch a cached asset (`aobake fetch --key`) before
//! deciding to submit.

use aobake_core::{Limits, bake::Bake, bake::bake_key};

use super::params::BakeRequestArgs;

/// Arguments of `aobake key`.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "The key is what `aobake bake`, `aobake submit` and the service give a bake of these files and parameters (its asset's header carries it), so a CI job can do: `KEY=$(aobake key FILE --method M ...)`, then `aobake fetch --key \"$KEY\" --out A.aob` (exit 4: not baked yet) or `aobake submit FILE --method M ... --wait`. The files are read and imported, and the parameters checked, as a bake here would (with this program's default import limits: a server's own limits, and its bound on a bake's work, are not checked); nothing is traced."
)]
pub(super) struct Args {
    #[command(flatten)]
    request: BakeRequestArgs,
}

/// Prints the key.
pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let r = &args.request;
    let params = r.params.params(r.method)?;
    let inputs = super::bake::load_inputs(&r.file, &r.clips, &Limits::default())?;
    // Refused here as the service would refuse it (an unknown clip, a
    // method the character cannot take).
    Bake::new(&inputs, params.clone())?;
    println!(
        "{}",
        bake_key(&inputs.character_digest, &inputs.clip_digests, &params)
    );
    Ok(())
}
