// Stands in for <GL/glext.h> on the include path of estimators/ and its unit tests:
// estimators see typed measurements and their declared model only (docs/design.md, section 3).
#error "estimators/ must not include <GL/glext.h>: convert in the scenario layer instead"
