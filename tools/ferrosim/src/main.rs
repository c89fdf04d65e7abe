//! `ferrosim serve | simulate FILE | replay TRACE` (see `--help`).

use clap::{Parser, Subcommand};
use ferrosim::simulate::{self, MachineKind, Options};
use ferrosim::tracking::{self, EncoderOptions, EncoderStrategy};
use ferrosim::{plots, replay, serve};
use std::path::PathBuf;

#[derive(Parser)]
#[command(name = "ferrosim", about = "Ferrostep's firmware core on a simulated board: a virtual printer, print simulation with plots, encoder-trace replay")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// A virtual printer on a pseudo-terminal: connect Printrun, OctoPrint
    /// or a terminal to the printed path (115200 baud is accepted; the
    /// line is simulated).
    Serve {
        #[arg(long, value_enum, default_value = "prusa")]
        machine: MachineKind,
        /// Virtual time per real time (1: real speed).
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
    },
    /// Run a whole G-code file in virtual time; print the figures and write
    /// the plots.
    Simulate {
        file: PathBuf,
        #[arg(long, value_enum, default_value = "prusa")]
        machine: MachineKind,
        /// Layer to draw (index from 0; default: the middle one).
        #[arg(long)]
        layer: Option<usize>,
        /// Where the PNG and SVG plots go.
        #[arg(long, default_value = "ferrosim-out")]
        out: PathBuf,
        /// Simulate the host's serial line at this rate (default: no limit).
        #[arg(long)]
        baud: Option<u32>,
        /// Skip the plots.
        #[arg(long)]
        no_plots: bool,
        /// Prusa only: run X and Y closed loop on their NSE-5310 encoders
        /// (SPEC §1) against the simulated axes, print the tracking error
        /// and alarms, plot `tracking_error`. `--encoders` alone: pid.
        #[arg(long, value_enum, num_args = 0..=1, default_missing_value = "pid", value_name = "STRATEGY")]
        encoders: Option<EncoderStrategy>,
        /// Kp of `--encoders p-ff` (default 4.3).
        #[arg(long, requires = "encoders")]
        kp: Option<f64>,
        /// γ of `--encoders pid`, in (0, 0.75] (default 0.5).
        #[arg(long, requires = "encoders")]
        gamma: Option<f64>,
    },
    /// Write a synthetic print (a 40 mm square, perimeters of 1 mm segments
    /// and infill, heated first) of about `minutes` to FILE, to try the
    /// other commands on.
    Synthetic {
        file: PathBuf,
        #[arg(long, default_value_t = 10.0)]
        minutes: f64,
    },
    /// Replay a recorded encoder trace: a CSV trace (hal-sim/traces/README.md)
    /// or a host log of an M828 capture (its TR: lines, X and Y).
    Replay {
        trace: PathBuf,
        /// Where the error plot goes (PNG and SVG).
        #[arg(long, default_value = "ferrosim-out")]
        out: PathBuf,
    },
}

fn main() {
    if let Err(error) = run(Cli::parse()) {
        eprintln!("ferrosim: {error}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<(), String> {
    match cli.command {
        Command::Serve { machine, speed } => {
            let mut printer = serve::VirtualPrinter::open(machine, speed)?;
            println!("{}", printer.path);
            eprintln!("ferrosim: virtual {machine:?} printer on {} at {speed}× real time; Ctrl-C stops it", printer.path);
            printer.run(|_| false)
        }
        Command::Simulate { file, machine, layer, out, baud, no_plots, encoders, kp, gamma } => {
            let encoder_options = match encoders {
                Some(_) if machine != MachineKind::Prusa => {
                    return Err(format!(
                        "--encoders: only the Prusa i3 (SPEC §1) has encoder-closed axes (NSE-5310 on X and Y); not the {machine:?}"
                    ))
                }
                Some(strategy) => Some(EncoderOptions::standard(strategy.strategy(kp, gamma)?)),
                None => None,
            };
            let gcode = std::fs::read_to_string(&file).map_err(|e| format!("{}: {e}", file.display()))?;
            let mut options = Options { machine, baud, ..Options::default() };
            if let Some(encoder) = &encoder_options {
                // One X/Y sample per loop tick: the reference pieces.
                options.xy_sample_ms = Some(tracking::sample_ms(encoder.loop_hz));
            }
            let bar = indicatif::ProgressBar::new(simulate::host_lines(&gcode).len() as u64);
            bar.set_style(
                indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} lines {msg}").map_err(|e| e.to_string())?,
            );
            let report = simulate::run(&gcode, &options, |sent, _| bar.set_position(sent as u64));
            bar.finish_and_clear();
            print!("{}", report.summary());
            let tracked = match &encoder_options {
                Some(encoder) => {
                    let tracked = tracking::track(&report, encoder)?;
                    print!("{}", tracked.summary());
                    Some(tracked)
                }
                None => None,
            };
            if !no_plots {
                let mut files = plots::simulation_plots(&report, &out, layer)?;
                if let Some(tracked) = &tracked {
                    files.extend(plots::tracking_plots(tracked, &out)?);
                }
                for path in files {
                    println!("wrote {}", path.display());
                }
            }
            if report.timed_out {
                return Err("the file did not finish".into());
            }
            Ok(())
        }
        Command::Synthetic { file, minutes } => {
            std::fs::write(&file, simulate::synthetic_print(minutes)).map_err(|e| format!("{}: {e}", file.display()))
        }
        Command::Replay { trace, out } => {
            let text = std::fs::read_to_string(&trace).map_err(|e| format!("{}: {e}", trace.display()))?;
            if replay::is_capture(&text) {
                let replayed = replay::replay_capture_text(&text)?;
                print!("{}", replayed.summary());
                std::fs::create_dir_all(&out).map_err(|e| e.to_string())?;
                let name = trace.file_stem().unwrap_or_default().to_string_lossy().into_owned();
                for (letter, axis) in ["x", "y"].iter().zip(&replayed.axes) {
                    for path in axis.plot(&out.join(format!("{name}_{letter}_error")))? {
                        println!("wrote {}", path.display());
                    }
                }
                return Ok(());
            }
            let replayed = replay::replay_text(&text)?;
            print!("{}", replayed.summary());
            std::fs::create_dir_all(&out).map_err(|e| e.to_string())?;
            let stem = out.join(trace.file_stem().unwrap_or_default()).with_extension("");
            for path in replayed.plot(&stem.with_file_name(format!("{}_error", stem.file_name().unwrap_or_default().to_string_lossy())))? {
                println!("wrote {}", path.display());
            }
            Ok(())
        }
    }
}
