# LCM message types: the only contract between the pipeline's processes.
#
# Included (once, include_guard) from lcmtypes/CMakeLists.txt and from services/transport.
# Outputs go to ${PROJECT_BINARY_DIR}/lcmtypes either way.
include_guard(GLOBAL)
#
# rcal_lcm_gen(TARGET name JAR jarname LCM_FILES f1.lcm ...)
#   - runs `lcm-gen --cpp` into ${RCAL_LCMTYPES_BINARY_DIR}/cpp and exposes the headers through
#     the INTERFACE target `name` (include as <rcal/imu_sample_t.hpp>);
#   - runs `lcm-gen --java`, javac and jar into ${RCAL_LCMTYPES_BINARY_DIR}/<jarname>.jar (the
#     classpath lcm-spy and lcm-logplayer-gui need to decode the rcal channels; target
#     `name`_jar, built by ALL). The jar is
#     skipped with a warning when javac, jar or /usr/share/java/lcm.jar is missing.
# Debian's LCM 1.3.1 ships no CMake package: LCM is found through pkg-config (`lcm`) or, when its
# pkg-config file cannot be resolved (it requires glib's .pc files), by header and library.

set(RCAL_LCMTYPES_BINARY_DIR ${PROJECT_BINARY_DIR}/lcmtypes)
find_program(LCM_GEN lcm-gen REQUIRED)
find_package(PkgConfig QUIET)
if(PKG_CONFIG_FOUND)
  pkg_check_modules(LCM QUIET IMPORTED_TARGET lcm)
endif()
if(NOT TARGET rcal_lcm)
  add_library(rcal_lcm INTERFACE)
  if(LCM_FOUND)
    target_link_libraries(rcal_lcm INTERFACE PkgConfig::LCM)
  else()
    find_path(LCM_INCLUDE_DIR lcm/lcm-cpp.hpp REQUIRED)
    find_library(LCM_LIBRARY lcm REQUIRED)
    target_include_directories(rcal_lcm INTERFACE ${LCM_INCLUDE_DIR})
    target_link_libraries(rcal_lcm INTERFACE ${LCM_LIBRARY})
  endif()
  # LCM 1.3's generated decoders store doubles through int64_t pointers (lcm_coretypes.h,
  # __double_decode_array): with strict aliasing GCC may read the fields back before the inlined
  # decode wrote them (seen: imu_sample_t.gyro read as 0 after decode at -O2). Every translation
  # unit that includes an LCM type gets -fno-strict-aliasing.
  target_compile_options(rcal_lcm INTERFACE -fno-strict-aliasing)
endif()

find_program(RCAL_JAVAC javac)
find_program(RCAL_JAR jar)
set(RCAL_LCM_JAR /usr/share/java/lcm.jar CACHE FILEPATH "LCM's Java library (liblcm-java)")

function(rcal_lcm_gen)
  cmake_parse_arguments(ARG "" "TARGET;JAR" "LCM_FILES" ${ARGN})
  set(cpp_dir ${RCAL_LCMTYPES_BINARY_DIR}/cpp)
  set(java_dir ${RCAL_LCMTYPES_BINARY_DIR}/java)
  set(headers)
  set(java_sources)
  set(lcm_abs)
  foreach(file ${ARG_LCM_FILES})
    get_filename_component(abs ${file} ABSOLUTE)
    list(APPEND lcm_abs ${abs})
    # The struct is named after the file: imu_sample.lcm -> rcal_imu_sample_t / rcal/imu_sample_t.
    get_filename_component(stem ${file} NAME_WE)
    list(APPEND headers ${cpp_dir}/rcal/${stem}_t.hpp)
    list(APPEND java_sources ${java_dir}/rcal/${stem}_t.java)
  endforeach()

  add_custom_command(
    OUTPUT ${headers}
    COMMAND ${CMAKE_COMMAND} -E make_directory ${cpp_dir}
    COMMAND ${LCM_GEN} --cpp --cpp-hpath ${cpp_dir} ${lcm_abs}
    DEPENDS ${lcm_abs}
    COMMENT "lcm-gen --cpp: ${ARG_TARGET}"
    VERBATIM)
  add_custom_target(${ARG_TARGET}_cpp DEPENDS ${headers})
  add_library(${ARG_TARGET} INTERFACE)
  add_dependencies(${ARG_TARGET} ${ARG_TARGET}_cpp)
  target_include_directories(${ARG_TARGET} INTERFACE ${cpp_dir})
  target_link_libraries(${ARG_TARGET} INTERFACE rcal_lcm)

  if(NOT ARG_JAR)
    return()
  endif()
  if(NOT RCAL_JAVAC OR NOT RCAL_JAR OR NOT EXISTS ${RCAL_LCM_JAR})
    message(WARNING "rcal_lcm_gen: javac, jar or ${RCAL_LCM_JAR} missing; ${ARG_JAR}.jar "
                    "(lcm-spy types) is not built")
    return()
  endif()
  set(jar_file ${RCAL_LCMTYPES_BINARY_DIR}/${ARG_JAR}.jar)
  set(class_dir ${RCAL_LCMTYPES_BINARY_DIR}/classes)
  add_custom_command(
    OUTPUT ${jar_file}
    COMMAND ${CMAKE_COMMAND} -E rm -rf ${java_dir} ${class_dir}
    COMMAND ${CMAKE_COMMAND} -E make_directory ${java_dir} ${class_dir}
    COMMAND ${LCM_GEN} --java --jpath ${java_dir} ${lcm_abs}
    COMMAND ${RCAL_JAVAC} -nowarn -source 8 -target 8 -cp ${RCAL_LCM_JAR} -d ${class_dir}
            ${java_sources}
    COMMAND ${RCAL_JAR} cf ${jar_file} -C ${class_dir} .
    DEPENDS ${lcm_abs}
    COMMENT "lcm-gen --java + javac + jar: ${ARG_JAR}.jar"
    VERBATIM)
  add_custom_target(${ARG_TARGET}_jar ALL DEPENDS ${jar_file})
  set_property(GLOBAL PROPERTY RCAL_LCMTYPES_JAR ${jar_file})
endfunction()

file(GLOB RCAL_LCM_FILES CONFIGURE_DEPENDS ${CMAKE_CURRENT_LIST_DIR}/*.lcm)
rcal_lcm_gen(TARGET rcal_lcmtypes JAR rcal_lcmtypes LCM_FILES ${RCAL_LCM_FILES})
