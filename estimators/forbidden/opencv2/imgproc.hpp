// Stands in for <opencv2/imgproc.hpp> on the include path of estimators/ and its unit tests (issue 22):
// estimators see typed measurements and their declared model only (docs/design.md, section 3).
#error "estimators/ must not include <opencv2/imgproc.hpp>: convert in the scenario layer instead"
