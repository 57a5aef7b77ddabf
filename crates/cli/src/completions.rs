//! `dpctl completions SHELL` and `dpctl man`: shell completions and man
//! pages generated from the clap definitions, so that they never drift
//! from the real options.

use anyhow::{Context, Result};
use clap::CommandFactory;
use std::io::Write;
use std::path::PathBuf;

/// Arguments of `dpctl completions`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Shell to write the completion script for (bash, zsh, fish,
    /// elvish, powershell).
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

/// Arguments of `dpctl man`.
#[derive(clap::Args, Debug)]
pub struct ManArgs {
    /// Write dpctl.1 and one page per subcommand (dpctl-master.1, …) into
    /// DIR instead of dpctl.1 on stdout.
    #[arg(long, value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
}

/// Print the completion script for `args.shell` on stdout.
pub fn run(args: Args) -> Result<()> {
    let mut cmd = crate::Cli::command();
    // clap_complete panics on a failed write: it writes into memory, and
    // standard output gets the whole script (a closed one is `Closed`).
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, "dpctl", &mut script);
    let mut out = crate::out::stdout();
    out.write_all(&script)?;
    out.flush()?;
    Ok(())
}

/// Print dpctl(1), or write every page into a directory.
pub fn man(args: ManArgs) -> Result<()> {
    let cmd = crate::Cli::command();
    match args.out_dir {
        Some(dir) => {
            std::fs::create_dir_all(&dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            clap_mangen::generate_to(cmd, &dir)
                .with_context(|| format!("writing man pages into {}", dir.display()))?;
        }
        None => {
            let mut out = crate::out::stdout();
            clap_mangen::Man::new(cmd).render(&mut out)?;
            out.flush()?;
        }
    }
    Ok(())
}
