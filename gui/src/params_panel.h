// The solver's parameter editor, generated from the one parameter table (lidef/deform_params.h): one editor
// per row, grouped by the table's groups, with the table's help, range and default as tooltip. Edits take
// effect only through Apply, which parses and validates them with the core library's own functions, so the
// studio accepts exactly what a scenario file or the command line accepts.
#pragma once
#include <QMetaType>
#include <QString>
#include <QWidget>
#include <string>
#include <vector>

#include "lidef/deform_params.h"

class QLabel;

namespace lidef::studio {

class ParamsPanel : public QWidget {
  Q_OBJECT

 public:
  explicit ParamsPanel(QWidget* parent = nullptr);

  // Makes `p` the applied parameters and shows them in the editors; clears any error mark. Emits nothing.
  void set_params(const lidef::DeformParams& p);
  // The parameters last applied (or set with set_params); pending edits are not included.
  lidef::DeformParams params() const { return applied_; }

  // Test hooks (and what the buttons do).
  // Puts `text` into the editor of the parameter `name`, as typing or choosing it would. False when there is
  // no such row, or when the editor cannot show `text` (a check box takes true/false, a choice box its
  // choices).
  bool set_text(const std::string& name, const std::string& text);
  // The text the editor of `name` currently shows ("" when there is no such row).
  std::string text(const std::string& name) const;
  // The Apply button: parses the edited rows into a copy of params() and validates the result. On success
  // makes it params() and emits params_applied; on failure marks the offending rows, shows the messages and
  // emits nothing. Returns success.
  bool apply();
  // The message(s) of the last failed apply, one line per offending row; "" after a successful one.
  QString error_text() const;
  // Whether the row `name` is marked as offending by the last apply.
  bool is_marked(const std::string& name) const;
  // The Defaults button: DeformParams{} into the editors (not applied).
  void load_defaults();
  // The Interactive preset button: reduced_dof = 100 and samples = 10000 into the editors (not applied).
  void load_interactive_preset();

 signals:
  // After a successful apply. needs_rebuild: changes_precomputation() (deform_params.h), so the solver must
  // be constructed again; otherwise DeformationSolver::set_params suffices.
  void params_applied(const lidef::DeformParams& p, bool needs_rebuild);

 private:
  struct Row {
    const lidef::ParamInfo* info = nullptr;
    QWidget* editor = nullptr;  // QLineEdit, QCheckBox or QComboBox
    QLabel* label = nullptr;
    std::string baseline;  // the text of params() in this row: a row is edited when its text differs
  };
  Row* find_row(const std::string& name);
  const Row* find_row(const std::string& name) const;
  static std::string editor_text(const Row& row);
  static bool set_editor_text(Row& row, const std::string& text);
  void show_params(const lidef::DeformParams& p);  // the editors only; baselines untouched
  void set_marked(Row& row, bool marked);
  void set_error(const QString& text);

  std::vector<Row> rows_;
  lidef::DeformParams applied_;
  QLabel* error_label_ = nullptr;
  QString error_text_;
};

}  // namespace lidef::studio

// For queued connections of params_applied (e.g. across a worker thread).
Q_DECLARE_METATYPE(lidef::DeformParams)
