# corofem_compile_shaders(OUT_DIR OUT_LIST shaders...)
# Compiles each GLSL compute shader NAME.comp twice with glslc (Debian: glslc), float and double
# (-DCOROFEM_DOUBLE), into OUT_DIR/NAME_float.inc and OUT_DIR/NAME_double.inc: SPIR-V words as a C
# initializer list (glslc -mfmt=c), which host/src/backends/vulkan/shaders.cpp includes. OUT_LIST
# receives the outputs (add them to the target's sources so that they are made before it).
function(corofem_compile_shaders OUT_DIR OUT_LIST)
  find_program(COROFEM_GLSLC glslc REQUIRED)
  file(GLOB deps ${PROJECT_SOURCE_DIR}/kernels/vulkan/*.glsl ${PROJECT_SOURCE_DIR}/kernels/shared/*.h)
  set(outputs)
  foreach(shader ${ARGN})
    get_filename_component(name ${shader} NAME_WE)
    foreach(precision float double)
      set(out ${OUT_DIR}/${name}_${precision}.inc)
      set(defines)
      if(precision STREQUAL "double")
        set(defines -DCOROFEM_DOUBLE)
      endif()
      add_custom_command(
        OUTPUT ${out}
        COMMAND ${CMAKE_COMMAND} -E make_directory ${OUT_DIR}
        COMMAND ${COROFEM_GLSLC} -fshader-stage=compute --target-env=vulkan1.1 -O -mfmt=c ${defines}
                -o ${out} ${shader}
        DEPENDS ${shader} ${deps}
        COMMENT "glslc ${name}.comp (${precision})"
        VERBATIM)
      list(APPEND outputs ${out})
    endforeach()
  endforeach()
  set(${OUT_LIST} ${outputs} PARENT_SCOPE)
endfunction()
