# What `cmake --install` lays out, the way Debian packages do (prefix /usr in the package):
#   bin/robocal                     the program
#   share/robocal/robots/           the robot library (`--robot NAME`; robocal finds it relative
#                                   to its own path, app/src/session/session_robot.cpp)
#   share/doc/robocal/              README.md and the parts' documents at their source paths (so
#                                   the README's links hold), examples/ (cells, vision files)
# and the Debian package built from it: `cpack --config build/release/CPackConfig.cmake`.
# Only the program is installed: robocal's own libraries are static and the tests stay here.
install(TARGETS robocal RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})

set(robocal_data ${CMAKE_INSTALL_DATADIR}/robocal)
set(robocal_doc ${CMAKE_INSTALL_DOCDIR})
install(DIRECTORY testdata/robots/ DESTINATION ${robocal_data}/robots
        FILES_MATCHING PATTERN "*.yaml" PATTERN "README.md")
foreach(doc README.md ARCHITECTURE.md app/SESSION.md calib/EXPORTS.md calib/identify/README.md
            planner/README.md robotio/README.md robotio/CAMERAS.md robotio/OPEN_LINK.md
            robotio/adapters/open_link_adapter.py vision/README.md
            vision/README_rig.md testdata/measurements/README.md docs/commands.md docs/figures.md
            docs/cluster.md docs/install.md docs/development.md)
  get_filename_component(dir ${doc} DIRECTORY)
  install(FILES ${doc} DESTINATION ${robocal_doc}/${dir})
endforeach()
# Cell files for `robocal plan` and the vision examples of the --help texts (not the bad one the
# tests feed in).
install(DIRECTORY testdata/cells/ DESTINATION ${robocal_doc}/examples/cells)
install(FILES testdata/vision/apriltag_4x3.yaml testdata/vision/camera_640x480.yaml
              testdata/vision/views_two.yaml
        DESTINATION ${robocal_doc}/examples/vision)

# The Debian package. Its runtime dependencies are read from the program's shared libraries by
# dpkg-shlibdeps (package dpkg-dev, which build-essential pulls in; CPack finds ELF files with
# `file`), so the package names exactly the libraries this build linked.
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME robocal)
set(CPACK_PACKAGE_VENDOR "robocal")
set(CPACK_PACKAGE_CONTACT "robocal maintainers <robocal@localhost>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "${PROJECT_DESCRIPTION}")
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION
    "robocal measures where a robot's tool really is with one or more cameras, identifies the \
robot's real geometry (6-axis arms and parallel robots: Delta, linear delta, Gantry-Tau, cable \
robots), proves the result on poses it did not use and exports the calibrated model.")
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_STRIP_FILES ON)
# Folders 0755 whatever the umask of the machine that builds the package.
set(CPACK_INSTALL_DEFAULT_DIRECTORY_PERMISSIONS
    OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE WORLD_READ WORLD_EXECUTE)
include(CPack)
