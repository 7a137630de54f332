# Embeds a text file as a C++ string constant: embed_text(<input> <output header> <symbol>).
function(organsmith_embed_text input output symbol)
  file(READ "${input}" text)
  set(delim "organsmith_embed")
  file(WRITE "${output}.tmp" "#pragma once\n// Generated from ${input}; edit that file instead.\ninline constexpr char ${symbol}[] = R\"${delim}(${text})${delim}\";\n")
  file(COPY_FILE "${output}.tmp" "${output}" ONLY_IF_DIFFERENT)
  set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS "${input}")
endfunction()
