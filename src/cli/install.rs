//! Installing like a desktop application: shell completions and the manual page generated from
//! the clap definitions, and the desktop entry, icons and project file type written into the
//! user's XDG folders (the files themselves live in `packaging/` and are built into the binary,
//! so an installed `makeit4d` needs no source tree).

use super::args::{Cli, InstallDesktopArgs};
use anyhow::Context;
use clap::CommandFactory;
use std::io::Write;
use std::path::{Path, PathBuf};

const DESKTOP_ENTRY: &str = include_str!("../../packaging/makeit4d.desktop");
const MIME_XML: &str = include_str!("../../packaging/makeit4d-mime.xml");
const ICON_SVG: &str = include_str!("../../packaging/makeit4d.svg");
const ICON_PNGS: [(u32, &[u8]); 6] = [
    (16, include_bytes!("../../packaging/icons/16x16.png")),
    (32, include_bytes!("../../packaging/icons/32x32.png")),
    (48, include_bytes!("../../packaging/icons/48x48.png")),
    (64, include_bytes!("../../packaging/icons/64x64.png")),
    (128, include_bytes!("../../packaging/icons/128x128.png")),
    (256, include_bytes!("../../packaging/icons/256x256.png")),
];

/// The completion script of `shell`.
pub(crate) fn completions(shell: clap_complete::Shell) -> Vec<u8> {
    let mut command = Cli::command();
    let mut out = Vec::new();
    clap_complete::generate(shell, &mut command, "makeit4d", &mut out);
    out
}

/// The manual page (roff).
pub(crate) fn manpage() -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    clap_mangen::Man::new(Cli::command())
        .render(&mut out)
        .context("making the manual page")?;
    Ok(out)
}

/// Writes `bytes` to standard output; a reader that stops early (`| head`) is not an error.
pub(crate) fn print_bytes(bytes: &[u8]) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(bytes).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(e).context("writing to standard output")
        }
        _ => Ok(()),
    }
}

/// The desktop entry with `Exec` and `TryExec` naming `exec` (quoted as the desktop entry
/// specification asks when the path has a space or a special character).
pub(crate) fn desktop_entry(exec: &Path) -> String {
    let path = exec.to_string_lossy();
    let quoted = if path
        .chars()
        .any(|c| c.is_whitespace() || "\"'\\><~|&;$*?#()`".contains(c))
    {
        let escaped: String = path
            .chars()
            .flat_map(|c| match c {
                '"' | '`' | '$' | '\\' => vec!['\\', c],
                _ => vec![c],
            })
            .collect();
        format!("\"{}\"", escaped.replace('\\', "\\\\"))
    } else {
        path.into_owned()
    };
    DESKTOP_ENTRY
        .lines()
        .map(|line| {
            if line.starts_with("Exec=") {
                format!("Exec={quoted} edit %f")
            } else if line.starts_with("TryExec=") {
                format!("TryExec={quoted}")
            } else {
                line.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

/// The files `install-desktop` writes, relative to the data folder, with their contents.
pub(crate) fn desktop_files(exec: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut files = vec![
        (
            PathBuf::from("applications/makeit4d.desktop"),
            desktop_entry(exec).into_bytes(),
        ),
        (
            PathBuf::from("mime/packages/makeit4d.xml"),
            MIME_XML.as_bytes().to_vec(),
        ),
        (
            PathBuf::from("icons/hicolor/scalable/apps/makeit4d.svg"),
            ICON_SVG.as_bytes().to_vec(),
        ),
    ];
    for (n, png) in ICON_PNGS {
        files.push((
            PathBuf::from(format!("icons/hicolor/{n}x{n}/apps/makeit4d.png")),
            png.to_vec(),
        ));
    }
    files
}

/// `makeit4d install-desktop`: writes every file atomically, then refreshes the MIME and
/// desktop databases where their tools exist (saying when they do not).
pub(crate) fn install_desktop(args: InstallDesktopArgs) -> anyhow::Result<()> {
    let data = match args.data_dir {
        Some(d) => d,
        None => match std::env::var_os("XDG_DATA_HOME").filter(|v| !v.is_empty()) {
            Some(d) => PathBuf::from(d),
            None => std::env::var_os("HOME")
                .map(|h| PathBuf::from(h).join(".local/share"))
                .context("neither XDG_DATA_HOME nor HOME is set; give --data-dir")?,
        },
    };
    let exec = match args.exec {
        Some(e) => e,
        None => std::env::current_exe().context("finding this executable")?,
    };
    for (relative, bytes) in desktop_files(&exec) {
        let path = data.join(&relative);
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
        }
        makeit4d::image_io::write_atomic(&path, &bytes)?;
        println!("wrote {}", path.display());
    }
    for (tool, dir) in [
        ("update-mime-database", data.join("mime")),
        ("update-desktop-database", data.join("applications")),
        ("gtk-update-icon-cache", data.join("icons/hicolor")),
    ] {
        let mut command = std::process::Command::new(tool);
        if tool == "gtk-update-icon-cache" {
            command.args(["--quiet", "--ignore-theme-index"]);
        }
        match command.arg(&dir).output() {
            Ok(o) if o.status.success() => println!("refreshed {} ({tool})", dir.display()),
            Ok(o) => eprintln!(
                "warning: {tool} {} failed: {}",
                dir.display(),
                String::from_utf8_lossy(&o.stderr).trim()
            ),
            Err(_) => eprintln!(
                "note: {tool} is not installed; the desktop picks the files up at next login"
            ),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn completions_name_every_subcommand() {
        for shell in [
            clap_complete::Shell::Bash,
            clap_complete::Shell::Zsh,
            clap_complete::Shell::Fish,
        ] {
            let text = String::from_utf8(completions(shell)).unwrap();
            for word in ["render", "eval", "working-size", "install-desktop"] {
                assert!(text.contains(word), "{shell:?} lacks {word}");
            }
        }
    }

    #[test]
    fn the_manual_page_is_roff_with_the_commands() {
        let text = String::from_utf8(manpage().unwrap()).unwrap();
        assert!(
            text.starts_with(".ie") || text.contains(".TH makeit4d"),
            "{text:.200}"
        );
        assert!(text.contains("render") && text.contains("completions"));
    }

    #[test]
    fn the_desktop_entry_runs_this_executable_quoted_when_needed() {
        let plain = desktop_entry(Path::new("/usr/local/bin/makeit4d"));
        assert!(
            plain.contains("\nExec=/usr/local/bin/makeit4d edit %f\n"),
            "{plain}"
        );
        assert!(plain.contains("\nTryExec=/usr/local/bin/makeit4d\n"));
        let spaced = desktop_entry(Path::new("/opt/my apps/makeit4d"));
        assert!(
            spaced.contains("\nExec=\"/opt/my apps/makeit4d\" edit %f\n"),
            "{spaced}"
        );
        assert!(spaced.contains("MimeType=") && spaced.contains("Icon=makeit4d"));
    }

    #[test]
    fn install_desktop_writes_every_file_into_the_data_folder() {
        let dir = tempfile::tempdir().unwrap();
        install_desktop(InstallDesktopArgs {
            data_dir: Some(dir.path().to_path_buf()),
            exec: Some(PathBuf::from("/usr/bin/makeit4d")),
        })
        .unwrap();
        for (relative, bytes) in desktop_files(Path::new("/usr/bin/makeit4d")) {
            let written = std::fs::read(dir.path().join(&relative)).unwrap();
            assert_eq!(written, bytes, "{}", relative.display());
        }
        let png = image::open(dir.path().join("icons/hicolor/48x48/apps/makeit4d.png")).unwrap();
        assert_eq!((png.width(), png.height()), (48, 48));
        // Where desktop-file-validate exists (Debian desktop-file-utils), the entry passes.
        let entry = dir.path().join("applications/makeit4d.desktop");
        if let Ok(o) = std::process::Command::new("desktop-file-validate")
            .arg(&entry)
            .output()
        {
            assert!(
                o.status.success() && o.stdout.is_empty(),
                "{}{}",
                String::from_utf8_lossy(&o.stdout),
                String::from_utf8_lossy(&o.stderr)
            );
        }
        // An unwritable data folder is a clear error.
        let file = dir.path().join("a-file");
        std::fs::write(&file, b"x").unwrap();
        let e = install_desktop(InstallDesktopArgs {
            data_dir: Some(file.clone()),
            exec: None,
        })
        .unwrap_err();
        assert!(format!("{e:#}").contains("a-file"), "{e:#}");
    }
}
