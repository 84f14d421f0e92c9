# corofem_embed_sources(OUT_CPP SYMBOL files...)
# Writes OUT_CPP defining
#   const corofem::EmbeddedSource SYMBOL[]; const std::size_t SYMBOL_count;
# with one {file name, text} entry per input file, so that kernel sources stay real files
# (readable by tools) and are still inside the library. Regenerated when any input changes.
function(corofem_embed_sources OUT_CPP SYMBOL)
  set(files ${ARGN})
  add_custom_command(
    OUTPUT ${OUT_CPP}
    COMMAND ${CMAKE_COMMAND} -DOUT=${OUT_CPP} -DSYMBOL=${SYMBOL} "-DFILES=${files}"
            -P ${PROJECT_SOURCE_DIR}/cmake/EmbedSourcesScript.cmake
    DEPENDS ${files} ${PROJECT_SOURCE_DIR}/cmake/EmbedSourcesScript.cmake
    COMMENT "Embedding ${SYMBOL} sources"
    VERBATIM)
endfunction()
