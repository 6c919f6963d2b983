# Run at every build (cmake -P): writes OUT, a source returning the commit the checkout at SOURCE is at, and only
# when that text changes, so a build after a new commit relinks with it and any other build recompiles nothing.
execute_process(COMMAND git rev-parse --short HEAD WORKING_DIRECTORY ${SOURCE}
                OUTPUT_VARIABLE commit OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
if(commit)
  execute_process(COMMAND git status --porcelain --untracked-files=no WORKING_DIRECTORY ${SOURCE}
                  OUTPUT_VARIABLE changes OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
  if(changes)
    set(commit "${commit} (with uncommitted changes)")
  endif()
endif()
set(text "// Written by cmake/build_commit.cmake at build time.\n#include \"experiments/build_commit.h\"\n\nconst char* canopy::build_commit() { return \"${commit}\"; }\n")
set(old "")
if(EXISTS ${OUT})
  file(READ ${OUT} old)
endif()
if(NOT old STREQUAL text)
  file(WRITE ${OUT} "${text}")
endif()
