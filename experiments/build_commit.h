#pragma once

namespace canopy {

// The commit of the checkout this binary was built from, "(with uncommitted changes)" after it when the build had
// some; empty when it was built outside a git checkout. Written at build time, not configure time.
const char* build_commit();

}  // namespace canopy
