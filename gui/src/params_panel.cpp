#include "params_panel.h"

#include <QCheckBox>
#include <QComboBox>
#include <QFormLayout>
#include <QGroupBox>
#include <QHBoxLayout>
#include <QLabel>
#include <QLineEdit>
#include <QPushButton>
#include <QScrollArea>
#include <QStringList>
#include <QVBoxLayout>
#include <algorithm>
#include <cmath>
#include <type_traits>
#include <variant>

#include "lidef/errors.h"

namespace lidef::studio {

namespace {

// The names of an enum parameter, from the one parameter table (empty for the other types).
QStringList choices(const ParamInfo& p) {
  QStringList out;
  for (const std::string& c : param_choices(p)) out << QString::fromStdString(c);
  return out;
}

QString group_title(const std::string& group) {
  if (group == "sampling") return "Subspace and sampling";
  if (group == "energy") return "Energy";
  if (group == "newton") return "Projected Newton";
  if (group == "certificate") return "Certificate";
  if (group == "weighting") return "Dynamic weighting";
  if (group == "execution") return "Execution";
  return QString::fromStdString(group);
}

template <class T>
constexpr bool is_integer_v = std::is_same_v<T, int> || std::is_same_v<T, long>;

QString range_text(double x, bool integral) {
  return integral ? QString::number(static_cast<long long>(x)) : QString::number(x, 'g', 10);
}

QString tooltip(const ParamInfo& p) {
  const DeformParams defaults;
  QString tip = QString::fromUtf8(p.help);
  std::visit(
      [&](auto member) {
        using T = std::decay_t<decltype(defaults.*member)>;
        if constexpr (std::is_enum_v<T>) {
          tip += "\nChoices: " + choices(p).join(", ");
        } else if constexpr (!std::is_same_v<T, bool> && !std::is_same_v<T, std::string>) {
          tip += QString("\nRange: [%1, %2]")
                     .arg(range_text(p.min, is_integer_v<T>), range_text(p.max, is_integer_v<T>));
        }
      },
      p.member);
  tip += "\nDefault: " + QString::fromStdString(param_value_string(defaults, p));
  return tip;
}

const char* kMarkedStyle = "background-color: #ffc0c0;";

}  // namespace

ParamsPanel::ParamsPanel(QWidget* parent) : QWidget(parent) {
  qRegisterMetaType<lidef::DeformParams>();
  const auto& table = deform_param_table();
  rows_.reserve(table.size());  // rows are addressed by pointer below; no reallocation

  auto* content = new QWidget;
  auto* content_layout = new QVBoxLayout(content);
  std::vector<std::pair<std::string, QFormLayout*>> groups;  // in order of first appearance in the table
  for (const ParamInfo& p : table) {
    if (is_test_hook(p)) continue;  // failure injection for the test suite, not a setting
    auto it = std::find_if(groups.begin(), groups.end(), [&](const auto& g) { return g.first == p.group; });
    if (it == groups.end()) {
      auto* box = new QGroupBox(group_title(p.group));
      auto* form = new QFormLayout(box);
      form->setFieldGrowthPolicy(QFormLayout::AllNonFixedFieldsGrow);
      content_layout->addWidget(box);
      groups.emplace_back(p.group, form);
      it = groups.end() - 1;
    }
    Row row;
    row.info = &p;
    const bool is_bool = std::holds_alternative<bool DeformParams::*>(p.member);
    if (is_bool) {
      row.editor = new QCheckBox;
    } else if (const QStringList c = choices(p); !c.isEmpty()) {
      auto* combo = new QComboBox;
      combo->addItems(c);
      row.editor = combo;
    } else {
      auto* edit = new QLineEdit;
      // Enter applies, as in any dialog-like form.
      connect(edit, &QLineEdit::returnPressed, this, [this] { apply(); });
      row.editor = edit;
    }
    const QString tip = tooltip(p);
    row.editor->setToolTip(tip);
    row.label = new QLabel(QString::fromUtf8(p.name));
    row.label->setToolTip(tip);
    it->second->addRow(row.label, row.editor);
    rows_.push_back(std::move(row));
  }
  content_layout->addStretch(1);

  auto* scroll = new QScrollArea;
  scroll->setWidget(content);
  scroll->setWidgetResizable(true);
  scroll->setHorizontalScrollBarPolicy(Qt::ScrollBarAlwaysOff);

  error_label_ = new QLabel;
  error_label_->setWordWrap(true);
  error_label_->setStyleSheet("color: #c00000;");
  error_label_->setTextInteractionFlags(Qt::TextSelectableByMouse);
  error_label_->setContentsMargins(6, 2, 6, 2);
  error_label_->hide();

  auto* defaults = new QPushButton("Defaults");
  defaults->setToolTip("Puts the default parameters into the editors (takes effect with Apply)");
  connect(defaults, &QPushButton::clicked, this, [this] { load_defaults(); });
  auto* preset = new QPushButton("Interactive preset");
  preset->setToolTip(
      "Puts reduced_dof = 100 and samples = 10000 into the editors (takes effect with Apply):\n"
      "small enough for >= 10 solver updates per second while dragging a handle on a 2-core machine");
  connect(preset, &QPushButton::clicked, this, [this] { load_interactive_preset(); });
  auto* apply_button = new QPushButton("Apply");
  apply_button->setToolTip("Checks the edited parameters and hands them to the solver");
  apply_button->setDefault(true);
  connect(apply_button, &QPushButton::clicked, this, [this] { apply(); });

  auto* buttons = new QHBoxLayout;
  buttons->addWidget(defaults);
  buttons->addWidget(preset);
  buttons->addStretch(1);
  buttons->addWidget(apply_button);

  auto* layout = new QVBoxLayout(this);
  layout->setContentsMargins(0, 0, 0, 0);
  layout->addWidget(scroll, 1);
  layout->addWidget(error_label_);
  layout->addLayout(buttons);

  set_params(DeformParams{});
}

ParamsPanel::Row* ParamsPanel::find_row(const std::string& name) {
  for (Row& r : rows_)
    if (name == r.info->name) return &r;
  return nullptr;
}

const ParamsPanel::Row* ParamsPanel::find_row(const std::string& name) const {
  return const_cast<ParamsPanel*>(this)->find_row(name);
}

std::string ParamsPanel::editor_text(const Row& row) {
  if (auto* check = qobject_cast<QCheckBox*>(row.editor)) return check->isChecked() ? "true" : "false";
  if (auto* combo = qobject_cast<QComboBox*>(row.editor)) return combo->currentText().toStdString();
  return static_cast<QLineEdit*>(row.editor)->text().trimmed().toStdString();
}

bool ParamsPanel::set_editor_text(Row& row, const std::string& text) {
  if (auto* check = qobject_cast<QCheckBox*>(row.editor)) {
    if (text != "true" && text != "false") return false;
    check->setChecked(text == "true");
    return true;
  }
  if (auto* combo = qobject_cast<QComboBox*>(row.editor)) {
    const int i = combo->findText(QString::fromStdString(text));
    if (i < 0) return false;
    combo->setCurrentIndex(i);
    return true;
  }
  static_cast<QLineEdit*>(row.editor)->setText(QString::fromStdString(text));
  return true;
}

void ParamsPanel::show_params(const DeformParams& p) {
  for (Row& r : rows_) {
    const std::string text = param_value_string(p, *r.info);
    if (auto* combo = qobject_cast<QComboBox*>(r.editor);
        combo && combo->findText(QString::fromStdString(text)) < 0)
      combo->addItem(QString::fromStdString(text));  // an unknown choice stays visible (validate reports it)
    set_editor_text(r, text);
  }
}

void ParamsPanel::set_params(const DeformParams& p) {
  applied_ = p;
  show_params(p);
  for (Row& r : rows_) {
    r.baseline = editor_text(r);
    set_marked(r, false);
  }
  set_error("");
}

bool ParamsPanel::set_text(const std::string& name, const std::string& text) {
  Row* row = find_row(name);
  return row && set_editor_text(*row, text);
}

std::string ParamsPanel::text(const std::string& name) const {
  const Row* row = find_row(name);
  return row ? editor_text(*row) : std::string();
}

bool ParamsPanel::apply() {
  static const std::string where = "parameters";
  for (Row& r : rows_) set_marked(r, false);
  DeformParams p = applied_;
  QStringList errors;
  // Only edited rows are parsed: an untouched row keeps its value exactly, whatever its text shows.
  for (Row& r : rows_) {
    const std::string text = editor_text(r);
    if (text == r.baseline) continue;
    try {
      set_param_from_text(p, r.info->name, text, where);
    } catch (const InputError& e) {
      set_marked(r, true);
      // Some messages ("'abc' is not a number ...") do not name the parameter.
      const std::string quoted = std::string("'") + r.info->name + "'";
      errors << QString::fromStdString(e.message().find(quoted) == std::string::npos
                                           ? r.info->name + std::string(": ") + e.message()
                                           : e.message());
    }
  }
  if (errors.isEmpty()) {
    try {
      validate_params(p, where);
    } catch (const InputError& e) {
      for (Row& r : rows_)
        if (e.message().find(std::string("'") + r.info->name + "'") != std::string::npos) {
          set_marked(r, true);
          break;
        }
      errors << QString::fromStdString(e.message());
    }
  }
  if (!errors.isEmpty()) {
    set_error(errors.join("\n"));
    return false;
  }

  const bool needs_rebuild = changes_precomputation(applied_, p);
  set_params(p);  // also shows the values in canonical form ("1e5" → "100000")
  emit params_applied(p, needs_rebuild);
  return true;
}

QString ParamsPanel::error_text() const {
  return error_text_;
}

bool ParamsPanel::is_marked(const std::string& name) const {
  const Row* row = find_row(name);
  return row && !row->editor->styleSheet().isEmpty();
}

void ParamsPanel::load_defaults() {
  show_params(DeformParams{});
}

void ParamsPanel::load_interactive_preset() {
  set_text("reduced_dof", "100");
  set_text("samples", "10000");
}

void ParamsPanel::set_marked(Row& row, bool marked) {
  row.editor->setStyleSheet(marked ? kMarkedStyle : "");
}

void ParamsPanel::set_error(const QString& text) {
  error_text_ = text;
  error_label_->setText(text);
  error_label_->setVisible(!text.isEmpty());
}

}  // namespace lidef::studio
