// Test main of lidef_studio_tests: a QApplication on a real X display (run under xvfb-run; the offscreen
// platform gives black grabs), then GoogleTest.
#include <QVTKOpenGLNativeWidget.h>
#include <gtest/gtest.h>

#include <QApplication>
#include <QSettings>
#include <QSurfaceFormat>
#include <clocale>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "lidef/blas_kernel.h"

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::process_environment());  // blas_kernel.h
  ::testing::InitGoogleTest(&argc, argv);
  for (int i = 1; i < argc; ++i)
    if (std::strcmp(argv[i], "--gtest_list_tests") == 0) return RUN_ALL_TESTS();  // no display needed
  if (!std::getenv("DISPLAY")) {
    std::fprintf(stderr,
                 "lidef_studio_tests: no DISPLAY; run under xvfb-run -a -s \"-screen 0 1280x800x24\"\n");
    return 1;
  }
  setenv("QT_QPA_PLATFORM", "xcb", 1);
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication app(argc, argv);
  // The window layout (QSettings) of the tests lives in a temporary folder, never in the user's settings.
  char settings_dir[] = "/tmp/lidef_studio_settings_XXXXXX";
  if (!mkdtemp(settings_dir)) return 1;
  QSettings::setDefaultFormat(QSettings::IniFormat);
  QSettings::setPath(QSettings::IniFormat, QSettings::UserScope, settings_dir);
  QApplication::setOrganizationName("lidef-tests");
  QApplication::setApplicationName("lidef-studio-tests");
  std::setlocale(LC_NUMERIC, "C");  // as lidef-studio does (gui/src/main.cpp): printf keeps its '.'
  const int rc = RUN_ALL_TESTS();
  std::filesystem::remove_all(settings_dir);
  return rc;
}
