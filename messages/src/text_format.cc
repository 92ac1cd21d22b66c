#include "vdyn/messages/text_format.h"

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/message.h>
#include <google/protobuf/text_format.h>

namespace vdyn::messages {
namespace {

namespace gp = google::protobuf;

class CollectErrors : public gp::io::ErrorCollector {
 public:
  void AddError(int line, gp::io::ColumnNumber column, const std::string& message) override {
    if (!text.empty()) text += "; ";
    text += "line " + std::to_string(line + 1) + ", column " + std::to_string(column + 1) + ": " +
            message;
  }
  void AddWarning(int line, gp::io::ColumnNumber column, const std::string& message) override {
    AddError(line, column, "warning: " + message);
  }
  std::string text;
};

}  // namespace

bool ParseTextFormat(const std::string& text, gp::Message& m, std::string* errors) {
  gp::TextFormat::Parser parser;
  CollectErrors collected;
  parser.RecordErrorsTo(&collected);
  if (parser.ParseFromString(text, &m)) return true;
  if (errors != nullptr) {
    *errors = collected.text.empty() ? std::string("cannot parse") : collected.text;
  }
  return false;
}

}  // namespace vdyn::messages
