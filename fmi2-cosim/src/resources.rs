//! The `fmuResourceLocation` argument of `fmi2Instantiate`: a URI of the FMU's
//! unpacked `resources` folder, which importers spell in many ways
//! (`file:///C:/x`, `file:/tmp/x`, `file://localhost/tmp/x`, percent-encoded,
//! or NULL when they have none).

use std::path::PathBuf;

/// Turns the URI into a local folder. `Ok(None)` when no location was given;
/// `Err` with the reason when the URI is not a local `file:` URI.
pub fn resource_dir(location: Option<&str>) -> Result<Option<PathBuf>, String> {
    let Some(location) = location else {
        return Ok(None);
    };
    if location.is_empty() {
        return Ok(None);
    }
    let url = url::Url::parse(location)
        .map_err(|e| format!("fmuResourceLocation {location:?} is not a URI: {e}"))?;
    if url.scheme() != "file" {
        return Err(format!(
            "fmuResourceLocation {location:?} is not a file: URI (scheme {})",
            url.scheme()
        ));
    }
    url.to_file_path()
        .map(Some)
        .map_err(|()| format!("fmuResourceLocation {location:?} is not a local path"))
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn spellings_of_the_same_folder_agree() {
        let expected = Some(PathBuf::from("/tmp/fmu dir/resources"));
        for uri in [
            "file:///tmp/fmu%20dir/resources",
            "file:/tmp/fmu%20dir/resources",
            "file://localhost/tmp/fmu%20dir/resources",
        ] {
            assert_eq!(resource_dir(Some(uri)).unwrap(), expected, "{uri}");
        }
    }

    #[test]
    fn missing_location_is_not_an_error() {
        assert_eq!(resource_dir(None).unwrap(), None);
        assert_eq!(resource_dir(Some("")).unwrap(), None);
    }

    #[test]
    fn other_schemes_are_refused_with_a_reason() {
        let err = resource_dir(Some("http://example.org/resources")).unwrap_err();
        assert!(err.contains("not a file: URI"), "{err}");
        assert!(resource_dir(Some("file://otherhost/x")).is_err());
    }
}
