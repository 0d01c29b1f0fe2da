#include "cnc_bridge/mtconnect/documents.h"

#include <tinyxml2.h>

#include <algorithm>
#include <charconv>
#include <cstring>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::mtconnect
{
namespace
{
using tinyxml2::XMLElement;

/// The element's name without its namespace prefix ("m:MTConnectStreams" -> "MTConnectStreams").
std::string_view localName(const XMLElement* e)
{
  std::string_view name = e->Name();
  const auto colon = name.find(':');
  return colon == std::string_view::npos ? name : name.substr(colon + 1);
}

std::string attribute(const XMLElement* e, const char* name)
{
  const char* value = e->Attribute(name);
  return value ? value : "";
}

/// First child element with the local name \p name, or nullptr.
const XMLElement* child(const XMLElement* parent, std::string_view name)
{
  for (const auto* c = parent->FirstChildElement(); c; c = c->NextSiblingElement())
  {
    if (localName(c) == name)
      return c;
  }
  return nullptr;
}

std::string beginning(std::string_view xml)
{
  std::string head(xml.substr(0, 80));
  for (char& c : head)
  {
    if (static_cast<unsigned char>(c) < 0x20)
      c = ' ';
  }
  return "'" + head + (xml.size() > 80 ? "...'" : "'");
}

uint64_t sequenceAttribute(const XMLElement* e, const char* name, bool required)
{
  const char* text = e->Attribute(name);
  if (!text)
  {
    if (required)
      throw ProtocolError(std::string("MTConnect header without ") + name);
    return 0;
  }
  uint64_t value = 0;
  const char* end = text + std::strlen(text);
  const auto [ptr, ec] = std::from_chars(text, end, value);
  if (ec != std::errc() || ptr != end)
    throw ProtocolError(std::string("MTConnect ") + e->Name() + " " + name + "=\"" + text +
                        "\" is not a sequence number");
  return value;
}

Header parseHeader(const XMLElement* root, bool streams)
{
  const XMLElement* h = child(root, "Header");
  if (!h)
    throw ProtocolError(std::string("MTConnect document <") + root->Name() + "> without a Header");
  Header header;
  header.instance_id = attribute(h, "instanceId");
  header.version = attribute(h, "version");
  header.creation_time = attribute(h, "creationTime");
  header.sender = attribute(h, "sender");
  header.buffer_size = sequenceAttribute(h, "bufferSize", false);
  header.first_sequence = sequenceAttribute(h, "firstSequence", streams);
  header.last_sequence = sequenceAttribute(h, "lastSequence", streams);
  header.next_sequence = sequenceAttribute(h, "nextSequence", streams);
  if (header.instance_id.empty())
    throw ProtocolError("MTConnect header without instanceId");
  return header;
}

void addDataItems(const XMLElement* component, const std::string& device, Device& out)
{
  const std::string component_type(localName(component));
  if (const XMLElement* items = child(component, "DataItems"))
  {
    for (const auto* d = items->FirstChildElement(); d; d = d->NextSiblingElement())
    {
      if (localName(d) != "DataItem")
        continue;
      DataItem item;
      item.id = attribute(d, "id");
      item.name = attribute(d, "name");
      item.type = attribute(d, "type");
      item.sub_type = attribute(d, "subType");
      item.category = attribute(d, "category");
      item.units = attribute(d, "units");
      item.native_units = attribute(d, "nativeUnits");
      item.component_type = component_type;
      item.component_name = attribute(component, "name");
      item.component_id = attribute(component, "id");
      item.device = device;
      out.data_items.push_back(std::move(item));
    }
  }
  if (const XMLElement* components = child(component, "Components"))
  {
    // tinyxml2 bounds the nesting depth while parsing, which bounds this recursion.
    for (const auto* c = components->FirstChildElement(); c; c = c->NextSiblingElement())
      addDataItems(c, device, out);
  }
}

void parseDevices(const XMLElement* root, Document& doc)
{
  const XMLElement* devices = child(root, "Devices");
  if (!devices)
    throw ProtocolError("MTConnectDevices without Devices");
  for (const auto* d = devices->FirstChildElement(); d; d = d->NextSiblingElement())
  {
    Device device;
    device.id = attribute(d, "id");
    device.name = attribute(d, "name");
    device.uuid = attribute(d, "uuid");
    device.is_agent = localName(d) == "Agent";
    addDataItems(d, device.name, device);
    doc.devices.push_back(std::move(device));
  }
}

Observation observationOf(const XMLElement* e, const std::string& device, const char* category)
{
  Observation o;
  o.device = device;
  o.element = std::string(localName(e));
  o.category = category;
  o.data_item_id = attribute(e, "dataItemId");
  o.name = attribute(e, "name");
  o.sub_type = attribute(e, "subType");
  o.sequence = sequenceAttribute(e, "sequence", false);
  o.timestamp = attribute(e, "timestamp");
  if (const char* text = e->GetText())
    o.value = text;
  if (std::strcmp(category, "CONDITION") == 0)
  {
    o.condition_type = attribute(e, "type");
    o.native_code = attribute(e, "nativeCode");
    o.native_severity = attribute(e, "nativeSeverity");
    o.qualifier = attribute(e, "qualifier");
  }
  return o;
}

void parseStreams(const XMLElement* root, Document& doc)
{
  const XMLElement* streams = child(root, "Streams");
  if (!streams)
    return;  // a heartbeat of an agent that leaves the empty element out
  for (const auto* ds = streams->FirstChildElement(); ds; ds = ds->NextSiblingElement())
  {
    const std::string device = attribute(ds, "name");
    for (const auto* cs = ds->FirstChildElement(); cs; cs = cs->NextSiblingElement())
    {
      for (const auto* group = cs->FirstChildElement(); group; group = group->NextSiblingElement())
      {
        const std::string_view kind = localName(group);
        const char* category = kind == "Samples"     ? "SAMPLE"
                               : kind == "Events"    ? "EVENT"
                               : kind == "Condition" ? "CONDITION"
                                                     : nullptr;
        if (!category)
          continue;
        for (const auto* e = group->FirstChildElement(); e; e = e->NextSiblingElement())
          doc.observations.push_back(observationOf(e, device, category));
      }
    }
  }
}

void parseErrors(const XMLElement* root, Document& doc)
{
  auto add = [&](const XMLElement* e)
  {
    const char* text = e->GetText();
    doc.errors.push_back({attribute(e, "errorCode"), text ? text : ""});
  };
  if (const XMLElement* errors = child(root, "Errors"))
  {
    for (const auto* e = errors->FirstChildElement(); e; e = e->NextSiblingElement())
      add(e);
  }
  else if (const XMLElement* e = child(root, "Error"))  // MTConnect 1.0
  {
    add(e);
  }
  if (doc.errors.empty())
    doc.errors.push_back({"UNKNOWN", "MTConnectError without an Error element"});
}
}  // namespace

std::string Document::errorText() const
{
  std::string text;
  for (const auto& e : errors)
  {
    if (!text.empty())
      text += "; ";
    text += e.code + ": " + e.text;
  }
  return text;
}

bool Document::hasError(const std::string& code) const
{
  return std::any_of(errors.begin(), errors.end(), [&](const AgentError& e) { return e.code == code; });
}

Document parseDocument(std::string_view xml, size_t max_bytes)
{
  if (xml.size() > max_bytes)
    throw ProtocolError("MTConnect document of " + std::to_string(xml.size()) + " bytes, more than the " +
                        std::to_string(max_bytes) + " allowed (~max_document_bytes)");
  tinyxml2::XMLDocument xml_doc;
  if (xml_doc.Parse(xml.data(), xml.size()) != tinyxml2::XML_SUCCESS)
  {
    throw ProtocolError(std::string("the agent's answer is not XML (") + xml_doc.ErrorStr() + "); it begins " +
                        beginning(xml));
  }
  const XMLElement* root = xml_doc.RootElement();
  if (!root)
    throw ProtocolError("the agent's answer holds no XML element; it begins " + beginning(xml));
  const std::string_view name = localName(root);
  Document doc;
  if (name == "MTConnectStreams")
  {
    doc.kind = DocumentKind::kStreams;
    doc.header = parseHeader(root, true);
    parseStreams(root, doc);
  }
  else if (name == "MTConnectDevices")
  {
    doc.kind = DocumentKind::kDevices;
    doc.header = parseHeader(root, false);
    parseDevices(root, doc);
  }
  else if (name == "MTConnectError")
  {
    doc.kind = DocumentKind::kError;
    if (child(root, "Header"))
      doc.header = parseHeader(root, false);
    parseErrors(root, doc);
  }
  else
  {
    throw ProtocolError("not an MTConnect document (root element <" + std::string(root->Name()) + ">); it begins " +
                        beginning(xml));
  }
  return doc;
}

const Device& selectDevice(const Document& probe, const std::string& name)
{
  std::string known;
  for (const auto& d : probe.devices)
  {
    if (d.is_agent)
      continue;
    if (name.empty() || d.name == name || d.uuid == name)
      return d;
    known += (known.empty() ? "" : ", ") + d.name;
  }
  throw ConfigError(name.empty() ? "the agent's probe lists no device"
                                 : "the agent has no device '" + name + "' (~device); it has: " + known);
}
}  // namespace cnc_bridge::mtconnect
