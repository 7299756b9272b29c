//! The guide's list of drivers (docs/modems.md) is the list built in
//! (`modemdriver::built_in::KINDS`): one row per driver, in its order,
//! naming it as a configuration does and its settings' section.

use modemdriver::built_in::KINDS;

/// The first `code` span of a Markdown table cell.
fn first_code(cell: &str) -> Option<&str> {
    let start = cell.find('`')? + 1;
    let len = cell[start..].find('`')?;
    Some(&cell[start..start + len])
}

#[test]
fn the_guide_lists_every_driver_built_in() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/modems.md");
    let guide = std::fs::read_to_string(path).expect("docs/modems.md");
    let header = "| driver (`driver_type`, or `driver_name`) | what it is | section |";
    let table = guide
        .split_once(header)
        .expect("the drivers' table in docs/modems.md")
        .1;
    let rows: Vec<(String, String)> = table
        .lines()
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|row| {
            let cells: Vec<&str> = row.split(" | ").collect();
            (
                first_code(cells[0]).unwrap_or("").to_string(),
                first_code(cells[cells.len() - 1]).unwrap_or("").to_string(),
            )
        })
        .collect();
    let built_in: Vec<(String, String)> = KINDS
        .iter()
        .map(|k| {
            (
                k.about().named.name().to_string(),
                k.about().section.unwrap_or("").to_string(),
            )
        })
        .collect();
    assert_eq!(rows, built_in);
}
