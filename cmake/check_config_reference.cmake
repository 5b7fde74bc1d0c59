# ctest config_reference: docs/CONFIG.md must be what `desplat_train --print-settings-reference`
# prints from the settings table (src/train/settings_table.cpp).
# Usage: cmake -DTRAIN=<desplat_train> -DPAGE=<docs/CONFIG.md> -DOUT=<scratch file> -P check_config_reference.cmake
execute_process(COMMAND ${TRAIN} --print-settings-reference OUTPUT_FILE ${OUT} RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${TRAIN} --print-settings-reference failed (exit ${rc})")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -E compare_files ${OUT} ${PAGE} RESULT_VARIABLE differ)
if(NOT differ EQUAL 0)
  message(FATAL_ERROR "${PAGE} does not match the settings table: regenerate it with "
                      "`desplat_train --print-settings-reference > docs/CONFIG.md` and commit it")
endif()
