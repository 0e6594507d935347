//! Names of files and directories that the run directories and the reports share:
//! [`sanitize_component`] makes an environment or model name a safe path component
//! (a sweep's run directories, a report's files, a run's copies of its morphology files).

/// A path component made of `[A-Za-z0-9_.+-]` only: `/`, `:` and `;` become `_`, `=`
/// becomes `-`, anything else `_` (so `team_reach/1_ant` -> `team_reach_1_ant`,
/// `shnn:assignment=hungarian;seed=3` -> `shnn_assignment-hungarian_seed-3`).
pub fn sanitize_component(s: &str) -> String {
    let out: String = s
        .chars()
        .map(|c| match c {
            '=' => '-',
            c if c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '+' | '-') => c,
            _ => '_',
        })
        .collect();
    if out.chars().all(|c| c == '.') { format!("_{out}") } else { out }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sanitized_names() {
        assert_eq!(sanitize_component("team_reach/1_ant"), "team_reach_1_ant");
        assert_eq!(
            sanitize_component("shnn:assignment=hungarian;translation=root_mean"),
            "shnn_assignment-hungarian_translation-root_mean"
        );
        assert_eq!(sanitize_component(".."), "_..");
        assert_eq!(sanitize_component("a b/c"), "a_b_c");
    }
}
