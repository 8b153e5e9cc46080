//! The `--port` patterns of `coolctl foxglove`.

/// Whether `name` (`node/path.port`) matches `pattern`, where `*` stands for any
/// characters (none included) and every other character for itself.
pub fn matches(pattern: &str, name: &str) -> bool {
    let pattern: Vec<char> = pattern.chars().collect();
    let name: Vec<char> = name.chars().collect();
    // The classic two-pointer match with one star to backtrack to: linear in the
    // lengths' product at worst, no recursion.
    let (mut p, mut n) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while n < name.len() {
        if p < pattern.len() && pattern[p] == '*' {
            star = Some((p, n));
            p += 1;
        } else if p < pattern.len() && pattern[p] == name[n] {
            p += 1;
            n += 1;
        } else if let Some((at, from)) = star {
            p = at + 1;
            n = from + 1;
            star = Some((at, from + 1));
        } else {
            return false;
        }
    }
    pattern[p..].iter().all(|c| *c == '*')
}

#[cfg(test)]
mod tests {
    use super::matches;

    #[test]
    fn stars_match_any_characters() {
        assert!(matches("robot/robot.base.scan", "robot/robot.base.scan"));
        assert!(matches("robot/robot.base.*", "robot/robot.base.scan"));
        assert!(matches("*", "robot/robot.base.scan"));
        assert!(matches("*/*.scan", "robot/robot.base.scan"));
        assert!(matches("robot/*", "robot/x.y"));
        assert!(matches("a*b*c", "abbbc"));
        assert!(!matches("robot/robot.base.*", "robot/robot.odometry"));
        assert!(!matches("*.scan", "robot/robot.base.scans"));
        assert!(!matches("", "robot/x.y"));
        assert!(!matches("other/*", "robot/x.y"));
    }
}
