// MTConnect documents: the reference agent's recorded probe, current, sample and error answers,
// the public sample devices of cppagent (MTConnect 1.1, with and without a namespace), prefixed
// element names of other agents, and bad input.
#include <gtest/gtest.h>

#include <algorithm>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mtconnect/documents.h"
#include "mtconnect_fixtures.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mtconnect;
using cnc_bridge::mtconnect::testing::fixture;
using cnc_bridge::mtconnect::testing::parseResponse;

namespace
{
Document recorded(const std::string& name)
{
  return parseDocument(parseResponse(fixture(name + ".http")).body);
}

const DataItem& item(const Device& d, const std::string& id)
{
  const auto it = std::find_if(d.data_items.begin(), d.data_items.end(), [&](const DataItem& i) { return i.id == id; });
  if (it == d.data_items.end())
    throw std::runtime_error("no data item " + id);
  return *it;
}

const Observation* find(const Document& doc, const std::string& id)
{
  for (const auto& o : doc.observations)
  {
    if (o.data_item_id == id)
      return &o;
  }
  return nullptr;
}
}  // namespace

TEST(MtconnectDocuments, RecordedProbe)
{
  const Document doc = recorded("probe");
  ASSERT_EQ(doc.kind, DocumentKind::kDevices);
  EXPECT_FALSE(doc.header.instance_id.empty());
  EXPECT_EQ(doc.header.buffer_size, 64u);
  const Device& mill = selectDevice(doc, "");
  EXPECT_EQ(mill.name, "mill");
  EXPECT_EQ(mill.uuid, "cnc-bridge-mill-0001");
  EXPECT_EQ(&selectDevice(doc, "cnc-bridge-mill-0001"), &mill);
  const DataItem& x = item(mill, "Xact");
  EXPECT_EQ(x.type, "POSITION");
  EXPECT_EQ(x.sub_type, "ACTUAL");
  EXPECT_EQ(x.category, "SAMPLE");
  EXPECT_EQ(x.units, "MILLIMETER");
  EXPECT_EQ(x.native_units, "INCH");
  EXPECT_EQ(x.component_type, "Linear");
  EXPECT_EQ(x.component_name, "X");
  EXPECT_EQ(item(mill, "exec").component_type, "Path");
  EXPECT_EQ(item(mill, "system").category, "CONDITION");
  EXPECT_EQ(item(mill, "avail").component_type, "Device");
  EXPECT_EQ(item(mill, "door_state").component_name, "door");
}

TEST(MtconnectDocuments, RecordedCurrent)
{
  const Document doc = recorded("current");
  ASSERT_EQ(doc.kind, DocumentKind::kStreams);
  const Header& h = doc.header;
  EXPECT_GT(h.next_sequence, h.first_sequence);
  EXPECT_EQ(h.next_sequence, h.last_sequence + 1);
  EXPECT_EQ(h.instance_id, recorded("probe").header.instance_id);
  const Observation* exec = find(doc, "exec");
  ASSERT_NE(exec, nullptr);
  EXPECT_EQ(exec->element, "Execution");
  EXPECT_EQ(exec->category, "EVENT");
  EXPECT_EQ(exec->value, "READY");
  EXPECT_EQ(exec->device, "mill");
  EXPECT_GT(exec->sequence, 0u);
  EXPECT_FALSE(exec->timestamp.empty());
  const Observation* x = find(doc, "Xact");
  ASSERT_NE(x, nullptr);
  EXPECT_EQ(x->category, "SAMPLE");
  EXPECT_DOUBLE_EQ(std::stod(x->value), 25.4);  // 1.0 inch from the adapter, in the agent's mm
  const Observation* system = find(doc, "system");
  ASSERT_NE(system, nullptr);
  EXPECT_EQ(system->category, "CONDITION");
  EXPECT_EQ(system->element, "Normal");
  EXPECT_EQ(system->condition_type, "SYSTEM");
}

TEST(MtconnectDocuments, RecordedStreamPartsCarryConditionsWithCodes)
{
  const auto parts = parseResponse(fixture("stream.http"), 0, false).parts;
  bool fault = false, warning = false;
  for (const auto& part : parts)
  {
    for (const auto& o : parseDocument(part).observations)
    {
      if (o.element == "Fault")
      {
        fault = true;
        EXPECT_EQ(o.native_code, "2001");
        EXPECT_EQ(o.value, "Spindle drive overload");
      }
      if (o.element == "Warning")
      {
        warning = true;
        EXPECT_EQ(o.native_code, "1010");
        EXPECT_EQ(o.qualifier, "HIGH");
        EXPECT_EQ(o.native_severity, "2");
      }
    }
  }
  EXPECT_TRUE(fault);
  EXPECT_TRUE(warning);
}

TEST(MtconnectDocuments, RecordedErrors)
{
  const Document range = recorded("sample_out_of_range");
  ASSERT_EQ(range.kind, DocumentKind::kError);
  EXPECT_TRUE(range.hasError("OUT_OF_RANGE"));
  EXPECT_NE(range.errorText().find("from"), std::string::npos) << range.errorText();
  const Document other = recorded("sample_not_found");
  ASSERT_EQ(other.kind, DocumentKind::kError);
  EXPECT_FALSE(other.hasError("OUT_OF_RANGE"));
}

TEST(MtconnectDocuments, PublicSampleDevicesOfOtherStyles)
{
  // cppagent's samples: MTConnect 1.1 documents with a default namespace, and with none at all.
  for (const char* name : {"samples/haas.xml", "samples/NoNamespace.xml"})
  {
    const Document doc = parseDocument(fixture(name));
    ASSERT_EQ(doc.kind, DocumentKind::kDevices) << name;
    EXPECT_FALSE(doc.header.version.empty());
    const Device& d = selectDevice(doc, "");
    EXPECT_GT(d.data_items.size(), 10u) << name;
    const auto x = std::find_if(d.data_items.begin(), d.data_items.end(),
                                [](const DataItem& i) { return i.type == "POSITION" && i.component_name == "X"; });
    ASSERT_NE(x, d.data_items.end()) << name;
  }
}

TEST(MtconnectDocuments, PrefixedElementsOfA2xAgent)
{
  const std::string xml = R"(<?xml version="1.0"?>
<m:MTConnectStreams xmlns:m="urn:mtconnect.org:MTConnectStreams:2.0" xmlns:x="urn:example.com:Ext">
 <m:Header instanceId="77" version="2.0.0.12" sender="a" bufferSize="131072" firstSequence="5" lastSequence="9" nextSequence="10" creationTime="2026-01-01T00:00:00Z"/>
 <m:Streams><m:DeviceStream name="VMC" uuid="v1"><m:ComponentStream component="Path" name="p" componentId="p1">
  <m:Events><m:Execution dataItemId="e" sequence="7" timestamp="2026-01-01T00:00:00.5Z">ACTIVE</m:Execution>
   <x:Vendor dataItemId="v" sequence="8" timestamp="2026-01-01T00:00:00.5Z">42</x:Vendor></m:Events>
  <m:Condition><m:Fault dataItemId="c" sequence="9" timestamp="2026-01-01T00:00:01Z" type="LOGIC_PROGRAM" nativeCode="E1">Bad</m:Fault></m:Condition>
 </m:ComponentStream></m:DeviceStream></m:Streams></m:MTConnectStreams>)";
  const Document doc = parseDocument(xml);
  ASSERT_EQ(doc.kind, DocumentKind::kStreams);
  EXPECT_EQ(doc.header.next_sequence, 10u);
  ASSERT_EQ(doc.observations.size(), 3u);
  EXPECT_EQ(doc.observations[0].element, "Execution");
  EXPECT_EQ(doc.observations[1].element, "Vendor");
  EXPECT_EQ(doc.observations[2].element, "Fault");
  EXPECT_EQ(doc.observations[2].condition_type, "LOGIC_PROGRAM");
  EXPECT_EQ(doc.observations[2].device, "VMC");
}

TEST(MtconnectDocuments, BadInputIsAClearProtocolError)
{
  auto error_of = [](const std::string& xml, size_t limit = 1u << 20u)
  {
    try
    {
      parseDocument(xml, limit);
    }
    catch (const ProtocolError& e)
    {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  const std::string current = parseResponse(fixture("current.http")).body;
  EXPECT_NE(error_of(current.substr(0, current.size() / 2)).find("not XML"), std::string::npos);
  EXPECT_NE(error_of("\x01\x02garbage").find("not XML"), std::string::npos);
  EXPECT_NE(error_of("<html><body>404</body></html>").find("not an MTConnect document"), std::string::npos);
  EXPECT_NE(error_of(current, 100).find("max_document_bytes"), std::string::npos);
  EXPECT_NE(error_of("<MTConnectStreams><Header instanceId=\"1\" firstSequence=\"1\" lastSequence=\"x\" "
                     "nextSequence=\"2\"/></MTConnectStreams>")
                .find("lastSequence"),
            std::string::npos);
  EXPECT_NE(error_of("<MTConnectStreams><Streams/></MTConnectStreams>").find("Header"), std::string::npos);
  // Deep nesting is bounded by the parser, not by our stack.
  std::string deep;
  for (int i = 0; i < 100000; ++i)
    deep += "<a>";
  EXPECT_NE(error_of(deep, 1u << 20u).find("not XML"), std::string::npos);
}
