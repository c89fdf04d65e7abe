use super::*;

fn d(mantissa: i32, digits: u8) -> Option<Decimal> {
    Some(Decimal::new(mantissa, digits))
}

#[test]
fn a_slicer_move_parses_into_exact_words() {
    let c = parse(b"G1 X10.5 Y-3 E0.04521 F1800").unwrap();
    assert_eq!(c.code, Code::G(1));
    assert_eq!(c.value(b'X'), Ok(d(105, 1)));
    assert_eq!(c.value(b'Y'), Ok(d(-3, 0)));
    assert_eq!(c.value(b'E'), Ok(d(4521, 5)));
    assert_eq!(c.value(b'F'), Ok(d(1800, 0)));
    assert_eq!(c.value(b'Z'), Ok(None));
}

#[test]
fn lower_case_compact_and_spaced_forms_are_the_same_command() {
    let reference = parse(b"G1 X10 Y5").unwrap();
    assert_eq!(parse(b"g1x10y5").unwrap(), reference);
    assert_eq!(parse(b"  G1   X 10\tY5  ").unwrap(), reference);
}

#[test]
fn comments_are_ignored() {
    let c = parse(b"G1 (move) X1 ; to the right").unwrap();
    assert_eq!(c.words().len(), 1);
    assert_eq!(c.value(b'X'), Ok(d(1, 0)));
    assert_eq!(parse(b"; only a comment"), Err(ParseError::Empty));
    assert_eq!(parse(b"(only) (comments)"), Err(ParseError::Empty));
}

#[test]
fn an_unclosed_comment_is_an_error() {
    assert_eq!(parse(b"G1 (move X1"), Err(ParseError::UnterminatedComment));
}

#[test]
fn malformed_numbers_name_their_word() {
    assert_eq!(parse(b"G1 X1.2.3"), Err(ParseError::BadNumber(b'X')));
    assert_eq!(parse(b"G1 x1e30"), Err(ParseError::BadNumber(b'X')));
    assert_eq!(parse(b"G1 Y-"), Err(ParseError::BadNumber(b'Y')));
    assert_eq!(parse(b"G1 Z99999999999"), Err(ParseError::NumberOutOfRange(b'Z')));
}

#[test]
fn a_flag_is_kept_and_reading_its_value_is_an_error() {
    let c = parse(b"G28 X Y").unwrap();
    assert!(c.has(b'X') && c.has(b'Y') && !c.has(b'Z'));
    assert_eq!(c.value(b'X'), Err(ParseError::WordWithoutValue(b'X')));
}

#[test]
fn bytes_that_are_not_gcode_are_rejected() {
    assert_eq!(parse(b"G1 X1 \0"), Err(ParseError::UnexpectedByte(0)));
    assert_eq!(parse("G1 X1 \u{e9}".as_bytes()), Err(ParseError::UnexpectedByte(0xc3)));
    assert_eq!(parse(b"#1=5"), Err(ParseError::UnexpectedByte(b'#')));
}

#[test]
fn a_repeated_letter_is_an_error() {
    assert_eq!(parse(b"G1 X1 X2"), Err(ParseError::DuplicateWord(b'X')));
}

#[test]
fn too_many_words_is_an_error() {
    assert_eq!(parse(b"G1 A1 B1 C1 D1 E1 F1 H1 I1 J1 K1 L1 O1 P1"), Err(ParseError::TooManyWords));
}

#[test]
fn the_command_number_must_be_a_whole_number() {
    assert_eq!(parse(b"G1.5 X1"), Err(ParseError::BadCommandNumber));
    assert_eq!(parse(b"M-3"), Err(ParseError::BadCommandNumber));
    assert_eq!(parse(b"M99999"), Err(ParseError::BadCommandNumber));
    assert_eq!(parse(b"G X1"), Err(ParseError::WordWithoutValue(b'G')));
}

#[test]
fn axis_words_alone_repeat_the_modal_motion() {
    let c = parse(b"X5 Y6").unwrap();
    assert_eq!(c.code, Code::Modal);
    assert_eq!(c.value(b'X'), Ok(d(5, 0)));
    assert_eq!(c.value(b'Y'), Ok(d(6, 0)));
}

#[test]
fn m117_keeps_its_text() {
    let line = b"M117 Printing 50% (layer 3); done";
    assert_eq!(parse(line).unwrap().code, Code::M(117));
    assert_eq!(text_argument(line), b"Printing 50% (layer 3)");
}

#[test]
fn tool_changes_parse() {
    assert_eq!(parse(b"T1").unwrap().code, Code::T(1));
}

#[test]
fn cam_lines_carry_mode_settings_beside_their_command() {
    let c = parse(b"G17 G90 G21").unwrap();
    assert_eq!((c.code, c.settings.as_slice()), (Code::G(17), &[Code::G(90), Code::G(21)][..]));
    // The code that acts is the command, wherever it stands.
    let c = parse(b"G91 G0 Z5").unwrap();
    assert_eq!((c.code, c.settings.as_slice()), (Code::G(0), &[Code::G(91)][..]));
    assert_eq!(c.words().len(), 1);
    let c = parse(b"G1 X10 F300 G90").unwrap();
    assert_eq!((c.code, c.settings.as_slice()), (Code::G(1), &[Code::G(90)][..]));
    assert_eq!(c.words().len(), 2);
    // The spindle word before its code: a modal line with M3 applied first.
    let c = parse(b"S10000 M3").unwrap();
    assert_eq!((c.code, c.settings.as_slice()), (Code::Modal, &[Code::M(3)][..]));
    let c = parse(b"G28 G91 Z0").unwrap();
    assert_eq!((c.code, c.settings.as_slice()), (Code::G(28), &[Code::G(91)][..]));
}

#[test]
fn a_second_acting_code_stays_an_ignored_word_as_in_marlin() {
    let c = parse(b"G28 G92").unwrap();
    assert_eq!(c.code, Code::G(28));
    assert!(c.settings.is_empty());
    assert_eq!(c.value(b'G').unwrap(), Some(Decimal::from_int(92)));
}

#[test]
fn a_percent_line_is_empty_and_too_many_codes_are_an_error() {
    assert_eq!(parse(b"%"), Err(ParseError::Empty));
    assert_eq!(parse(b" % "), Err(ParseError::Empty));
    assert_eq!(parse(b"G17 G90 G21 G94 G40 G49 G80 G54"), Err(ParseError::TooManyCodes));
}

#[test]
fn mode_setting_codes_are_exactly_the_modal_groups() {
    for n in 0..=1000u16 {
        let g = matches!(n, 17..=21 | 40 | 49 | 53..=59 | 61 | 64 | 80 | 90 | 91 | 93 | 94);
        let m = matches!(n, 3..=5 | 7..=9);
        assert_eq!(is_mode_setting(Code::G(n)), g, "G{n}");
        assert_eq!(is_mode_setting(Code::M(n)), m, "M{n}");
        assert!(!is_mode_setting(Code::T(n)));
    }
    assert!(!is_mode_setting(Code::Modal) && !is_mode_setting(Code::Other));
}
