# One INTERFACE target carries the warning flags (and the sanitizer flags); every target of ours links it.
add_library(texstream_warnings INTERFACE)
add_library(texstream::warnings ALIAS texstream_warnings)
target_compile_options(texstream_warnings INTERFACE
  -Wall -Wextra -Werror -Wshadow -Wnon-virtual-dtor -Wcast-align -Wunused -Woverloaded-virtual
  -Wnull-dereference -Wdouble-promotion -Wformat=2 -Wimplicit-fallthrough)

if(TEXSTREAM_SANITIZE)
  if(TEXSTREAM_SANITIZE STREQUAL "thread")
    set(_san_flags -fsanitize=thread)
    # GCC 12 warns (-Wtsan) that TSan does not model std::atomic_thread_fence; the doorbell's fences are
    # documented and paired, so keep the warning visible but not fatal.
    target_compile_options(texstream_warnings INTERFACE -Wno-error=tsan)
  elseif(TEXSTREAM_SANITIZE STREQUAL "address,undefined" OR TEXSTREAM_SANITIZE STREQUAL "address"
         OR TEXSTREAM_SANITIZE STREQUAL "undefined")
    set(_san_flags -fsanitize=${TEXSTREAM_SANITIZE} -fno-sanitize-recover=undefined)
  else()
    message(FATAL_ERROR "TEXSTREAM_SANITIZE must be empty, 'address,undefined' or 'thread', not '${TEXSTREAM_SANITIZE}'")
  endif()
  # Sanitizer instrumentation makes GCC 12 report -Wmaybe-uninitialized inside libstdc++ (std::regex,
  # std::function) and, with TSan, -Wnull-dereference inside basic_string.h: false positives that the normal
  # build does not show. Keep them visible, not fatal. Debug info is the build type's (a `-g` here overrode
  # the CI stages' -g1 and cost 20 % of their compile time; docs/design/ci_time.md).
  target_compile_options(texstream_warnings INTERFACE ${_san_flags} -fno-omit-frame-pointer
                         -Wno-error=maybe-uninitialized -Wno-error=null-dereference)
  target_link_options(texstream_warnings INTERFACE ${_san_flags})
endif()
