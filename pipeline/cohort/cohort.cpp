// Cohort files: reading, validating and resolving each row into the study's complete case.
#include "pipeline/cohort/cohort.h"
#include "pipeline/output/tool_info.h"

#include "core/csv.h"
#include "core/errors.h"
#include "core/file_io.h"
#include "core/sha256.h"
#include "core/toml_parse.h"
#include "pipeline/case/case_file.h"

#include <toml++/toml.h>

#include <regex>
#include <set>
#include <sstream>

namespace fs = std::filesystem;

namespace organsmith {

namespace {

/// Sizes and modification times of every file of the input: a study is redone when its input
/// changed, without reading the pixels here.
std::string input_signature(const std::string& input) {
  if (input == "phantom" || input.rfind("pacs://", 0) == 0) return input;
  std::error_code ec;
  std::ostringstream out;
  auto one = [&](const fs::path& p) {
    const auto size = fs::file_size(p, ec);
    const auto time = fs::last_write_time(p, ec).time_since_epoch().count();
    out << p.string() << ' ' << (ec ? 0 : size) << ' ' << time << '\n';
  };
  if (fs::is_directory(input, ec)) {
    std::vector<fs::path> files;
    for (auto it = fs::recursive_directory_iterator(input, ec); !ec && it != fs::recursive_directory_iterator();
         it.increment(ec))
      if (it->is_regular_file(ec)) files.push_back(it->path());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) one(f);
  } else {
    one(input);
  }
  return out.str();
}

/// A CSV field as a TOML value: TOML syntax when it is a value ("3", "4.5", "true", "[1, 2]",
/// "\"text\""), else the text as a string.
bool set_value(toml::table& t, const std::string& key, const std::string& text) {
  try {
    toml::table parsed = toml::parse("v = " + text);
    if (toml::node* v = parsed.get("v")) {
      t.insert_or_assign(key, std::move(*v));
      return true;
    }
  } catch (const toml::parse_error&) {
  }
  t.insert_or_assign(key, text);
  return true;
}

std::vector<std::string> split_words(const std::string& text) {
  std::vector<std::string> out;
  std::string word;
  for (char ch : text + " ") {
    if (ch == ' ' || ch == ';' || ch == '\t' || ch == ',') {
      if (!word.empty()) out.push_back(word);
      word.clear();
    } else {
      word += ch;
    }
  }
  return out;
}

std::string column_ref(const CsvTable& t, const CsvRow& row, std::size_t col) {
  return "line " + std::to_string(row.line) + ", column " + std::to_string(col + 1) + " (" +
         t.header.fields[col] + ")";
}

}  // namespace

CohortPlan load_cohort(const fs::path& cohort_file, const fs::path& shared_case, const fs::path& out_dir) {
  CohortPlan plan;
  plan.cohort_file = fs::absolute(cohort_file);
  plan.out_dir = fs::absolute(out_dir).lexically_normal();
  const std::string text = read_input_file(cohort_file, "the cohort file", ExitCode::case_file,
                                           "give a CSV file whose header is at least id,input");
  const CsvTable table = parse_csv(text, cohort_file, ExitCode::case_file);

  std::string shared_text = default_case_text();
  fs::path origin = plan.cohort_file;
  if (!shared_case.empty()) {
    plan.shared_case = fs::absolute(shared_case);
    const auto t = read_file(shared_case);
    if (!t) throw InputError(ExitCode::input_not_found, "cannot read the shared case file (--case)", shared_case);
    shared_text = *t;
    origin = plan.shared_case;
    (void)load_case_file(shared_case);  // the shared case alone must be valid (its own errors first)
  }
  const toml::table shared = parse_toml(shared_text, origin, "the shared case file", "fix the syntax");

  std::vector<std::string> errors;
  const int id_col = table.column("id"), input_col = table.column("input");
  if (id_col < 0) errors.push_back("line " + std::to_string(table.header.line) + ": the header has no 'id' column");
  if (input_col < 0)
    errors.push_back("line " + std::to_string(table.header.line) + ": the header has no 'input' column");
  std::set<std::string> header_seen;
  for (std::size_t c = 0; c < table.header.fields.size(); ++c) {
    const std::string& h = table.header.fields[c];
    if (!header_seen.insert(h).second)
      errors.push_back("line " + std::to_string(table.header.line) + ", column " + std::to_string(c + 1) +
                       ": the column '" + h + "' appears twice");
    const bool known = h == "id" || h == "input" || h == "organs" || h.find('.') != std::string::npos;
    if (!known)
      errors.push_back("line " + std::to_string(table.header.line) + ", column " + std::to_string(c + 1) + ": '" + h +
                       "' is no cohort column (id, input, organs, seed_lps_mm.<organ>, seed_ijk.<organ>, "
                       "reference.<organ>, or a case option as <table>.<key>)");
  }
  if (table.rows.empty()) errors.push_back("the cohort has no study (only a header)");
  if (!errors.empty() || id_col < 0 || input_col < 0) goto report;

  {
    const std::regex id_rule("[A-Za-z0-9][A-Za-z0-9._-]{0,63}");
    std::set<std::string> ids;
    const fs::path base = plan.cohort_file.parent_path();
    for (const CsvRow& row : table.rows) {
      const std::size_t before = errors.size();
      CohortStudy s;
      s.line = row.line;
      s.id = row.fields[std::size_t(id_col)];
      if (!std::regex_match(s.id, id_rule) || s.id == "cohort")
        errors.push_back(column_ref(table, row, std::size_t(id_col)) + ": the id '" + s.id +
                         "' is not a folder name (letters, digits, '.', '_', '-'; up to 64; not 'cohort')");
      else if (!ids.insert(s.id).second)
        errors.push_back(column_ref(table, row, std::size_t(id_col)) + ": the id '" + s.id + "' is used twice");
      const std::string& input = row.fields[std::size_t(input_col)];
      if (input.empty()) {
        errors.push_back(column_ref(table, row, std::size_t(input_col)) + ": no input given");
      } else if (input == "phantom" || input.rfind("pacs://", 0) == 0) {
        s.input = input;  // a PACS study: the shared case names the PACS ([pacs.<name>])
      } else {
        s.input = (base / input).lexically_normal().string();
        if (!fs::exists(s.input))
          errors.push_back(column_ref(table, row, std::size_t(input_col)) + ": the input does not exist");
      }

      toml::table study = shared;
      auto* case_table = study["case"].as_table();
      if (!case_table) {
        study.insert_or_assign("case", toml::table{});
        case_table = study["case"].as_table();
      }
      case_table->insert_or_assign("name", s.id);
      case_table->insert_or_assign("input", s.input);
      std::vector<std::size_t> order;  // the organs column first: seeds name its organs
      for (std::size_t c = 0; c < row.fields.size(); ++c)
        if (table.header.fields[c] == "organs") order.insert(order.begin(), c);
        else order.push_back(c);
      for (const std::size_t c : order) {
        const std::string& h = table.header.fields[c];
        const std::string& v = row.fields[c];
        if (v.empty() || h == "id" || h == "input") continue;
        if (h == "organs") {
          toml::array organs;
          for (const auto& name : split_words(v)) organs.push_back(toml::table{{"name", name}});
          if (organs.empty()) errors.push_back(column_ref(table, row, c) + ": no organ named");
          study.insert_or_assign("organ", std::move(organs));
          continue;
        }
        const std::string head = h.substr(0, h.find('.')), rest = h.substr(h.find('.') + 1);
        if (head == "reference") {
          s.references[rest] = (base / v).lexically_normal();
          if (!fs::exists(s.references[rest]))
            errors.push_back(column_ref(table, row, c) + ": the reference label map does not exist");
          continue;
        }
        if (head == "seed_lps_mm" || head == "seed_ijk") {
          const auto words = split_words(v);
          toml::array xyz;
          bool ok = words.size() == 3;
          for (const auto& w : words) {
            char* end = nullptr;
            const double x = std::strtod(w.c_str(), &end);
            ok = ok && end && *end == '\0' && std::isfinite(x);
            xyz.push_back(x);
          }
          if (!ok) {
            errors.push_back(column_ref(table, row, c) + ": '" + v + "' is not three numbers \"x y z\"");
            continue;
          }
          bool found = false;
          if (auto* organs = study["organ"].as_array())
            for (auto& o : *organs)
              if (auto* ot = o.as_table(); ot && ot->get("name") && ot->get("name")->value_or(std::string()) == rest) {
                ot->insert_or_assign(head, xyz);
                found = true;
              }
          if (!found)
            errors.push_back(column_ref(table, row, c) + ": the organ '" + rest +
                             "' is not among the study's organs (put the organs column before the seeds)");
          continue;
        }
        // <table>.<key>[.<key>…]: a case-file option
        toml::table* t = &study;
        std::string path = h;
        for (std::size_t dot; (dot = path.find('.')) != std::string::npos; path = path.substr(dot + 1)) {
          const std::string part = path.substr(0, dot);
          if (!(*t)[part].is_table()) t->insert_or_assign(part, toml::table{});
          t = (*t)[part].as_table();
        }
        set_value(*t, path, v);
      }
      std::ostringstream toml_text;
      toml_text << study;
      s.case_toml = toml_text.str();
      s.case_origin = origin;
      if (errors.size() == before) {
        try {
          (void)parse_case(s.case_toml, origin);
        } catch (const Error& e) {
          errors.push_back("line " + std::to_string(row.line) + " (study '" + s.id + "'): " + e.message() +
                           (e.hint().empty() ? "" : " — " + e.hint()));
        }
      }
      std::string refs;
      for (const auto& [organ, p] : s.references) refs += organ + "=" + input_signature(p.string());
      s.fingerprint = sha256_hex(tool_version() + "\n" + tool_git_commit() + "\n" + s.case_toml + "\n" +
                                 input_signature(s.input) + "\n" + refs);
      plan.studies.push_back(std::move(s));
    }
  }

report:
  if (!errors.empty()) {
    std::string all;
    for (const auto& e : errors) all += "\n  " + e;
    throw CaseFileError("the cohort file has " + std::to_string(errors.size()) + " error" +
                            (errors.size() == 1 ? "" : "s") + ":" + all,
                        cohort_file, "see README.md, 'Cohorts' for the columns");
  }
  return plan;
}

nlohmann::json to_json(const CohortPlan& plan) {
  nlohmann::json studies = nlohmann::json::array();
  for (const auto& s : plan.studies) {
    nlohmann::json refs = nlohmann::json::object();
    for (const auto& [organ, p] : s.references) refs[organ] = p.string();
    studies.push_back({{"id", s.id}, {"line", s.line}, {"case_toml", s.case_toml}, {"case_origin", s.case_origin.string()},
                       {"input", s.input}, {"references", refs}, {"fingerprint", s.fingerprint}});
  }
  return {{"cohort_file", plan.cohort_file.string()}, {"shared_case", plan.shared_case.string()},
          {"out_dir", plan.out_dir.string()}, {"studies", studies}};
}

CohortPlan cohort_plan_from_json(const nlohmann::json& j, const fs::path& file) {
  try {
    CohortPlan plan;
    plan.cohort_file = j.at("cohort_file").get<std::string>();
    plan.shared_case = j.at("shared_case").get<std::string>();
    plan.out_dir = j.at("out_dir").get<std::string>();
    for (const auto& s : j.at("studies")) {
      CohortStudy st;
      st.id = s.at("id");
      st.line = s.at("line");
      st.case_toml = s.at("case_toml");
      st.case_origin = s.at("case_origin").get<std::string>();
      st.input = s.at("input");
      for (const auto& [organ, p] : s.at("references").items()) st.references[organ] = p.get<std::string>();
      st.fingerprint = s.at("fingerprint");
      plan.studies.push_back(std::move(st));
    }
    return plan;
  } catch (const nlohmann::json::exception& e) {
    throw InputError(ExitCode::corrupt_file, std::string("not a cohort plan: ") + e.what(), file,
                     "rerun `organsmith cohort` to write it again");
  }
}

std::string redact_study_text(const CohortStudy& study, std::string text) {
  if (study.input.empty() || study.input == "phantom") return text;
  std::string needle = study.input;
  if (needle.rfind("pacs://", 0) == 0) needle = needle.substr(needle.rfind('/') + 1);  // the StudyInstanceUID
  if (needle.empty()) return text;
  for (std::size_t at; (at = text.find(needle)) != std::string::npos;) text.replace(at, needle.size(), "<input>");
  return text;
}

nlohmann::json to_json(const StudyStatus& s) {
  return {{"id", s.id}, {"exit_code", s.exit_code}, {"message", s.message}, {"seconds", s.seconds},
          {"fingerprint", s.fingerprint}};
}

StudyStatus study_status_from_json(const nlohmann::json& j) {
  StudyStatus s;
  s.id = j.value("id", "");
  s.exit_code = j.value("exit_code", -1);
  s.message = j.value("message", "");
  s.seconds = j.value("seconds", 0.0);
  s.fingerprint = j.value("fingerprint", "");
  return s;
}

}  // namespace organsmith
