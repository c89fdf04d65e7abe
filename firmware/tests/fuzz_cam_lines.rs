//! Property tests of CAM-style lines (several mode codes beside a command,
//! Grbl's block): in whatever order the codes come, the modes they set
//! apply before the line's move, every line gets one `ok`, and a line the
//! firmware refuses moves nothing.

use hal_sim::board::SimBoard;
use proptest::prelude::*;

fn config() -> ProptestConfig {
    ProptestConfig { cases: 300, ..ProptestConfig::default() }
}

/// Mode codes that change nothing a move depends on here.
const NEUTRAL: &[&str] = &["G17", "G21", "G40", "G49", "G54", "G61", "G64", "G80", "G94", "M5", "M9"];

fn position_x(board: &mut SimBoard) -> String {
    let output = board.run_gcode("M114\n", 5_000);
    output.split("X:").nth(1).and_then(|x| x.split(' ').next()).unwrap_or("?").to_string()
}

proptest! {
    #![proptest_config(config())]

    /// `G91` (or `G90`) anywhere on a move's line decides how that move's
    /// X is read, whatever neutral modes stand around it.
    #[test]
    fn the_distance_mode_on_a_line_governs_its_move(
        relative in any::<bool>(),
        before in proptest::collection::vec(0..NEUTRAL.len(), 0..3),
        after in proptest::collection::vec(0..NEUTRAL.len(), 0..2),
        mode_first in any::<bool>(),
        x in 1u32..50,
    ) {
        let mut board = SimBoard::booted();
        // Start at X 10, absolute.
        prop_assert_eq!(board.run_gcode("G90\nG1 X10 F6000\n", 20_000), "ok\nok\n");
        let mode = if relative { "G91" } else { "G90" };
        let mut words: Vec<String> = before.iter().map(|&i| NEUTRAL[i].to_string()).collect();
        let motion = format!("G1 X{x}");
        if mode_first {
            words.push(mode.into());
            words.push(motion);
        } else {
            words.push(motion);
            words.push(mode.into());
        }
        words.extend(after.iter().map(|&i| NEUTRAL[i].to_string()));
        let line = words.join(" ");
        let output = board.run_gcode(&format!("{line}\n"), 20_000);
        prop_assert!(output.ends_with("ok\n") && output.matches("ok").count() == 1, "{line}: {output}");
        prop_assert!(!output.contains("Error"), "{line}: {output}");
        let expected = if relative { 10 + x } else { x };
        prop_assert_eq!(position_x(&mut board), format!("{expected}.00"), "{}", line);
    }

    /// An unsupported mode anywhere on a line (inverse-time feed) refuses
    /// the whole line: the move on it does not run, nor the next one.
    #[test]
    fn an_unsupported_feed_mode_on_a_line_moves_nothing(
        before in proptest::collection::vec(0..NEUTRAL.len() - 3, 0..3),
        x in 1u32..50,
    ) {
        let mut board = SimBoard::booted();
        let mut words: Vec<String> = before.iter().map(|&i| NEUTRAL[i].to_string()).collect();
        words.push("G93".into());
        words.push(format!("G1 X{x} F6000"));
        let line = words.join(" ");
        let output = board.run_gcode(&format!("{line}\nG1 X5\n"), 20_000);
        let refusal = "Error:G93 is not supported: moves are refused until G94\nok\n";
        prop_assert_eq!(output, refusal.repeat(2), "{}", line);
        prop_assert_eq!(board.steps.positions(), [0, 0, 0, 0]);
    }

    /// A work system's zero moves every target on by exactly its offset.
    #[test]
    fn a_work_offset_shifts_the_target_by_itself(system in 1u32..=6, zero in 0u32..40, x in 0u32..40) {
        let mut board = SimBoard::booted();
        let line = format!("G10 L2 P{system} X{zero}\nG{} G0 X{x}\n", 53 + system);
        prop_assert_eq!(board.run_gcode(&line, 20_000), "ok\nok\n");
        prop_assert_eq!(board.steps.positions()[0], i64::from(zero + x) * 100);
    }
}
